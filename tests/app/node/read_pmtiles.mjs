// Read a PMTiles archive with the pmtiles JS reader (as MapLibre's pmtiles protocol does) from a local file.
// Usage: node read_pmtiles.mjs FILE.pmtiles z/x/y ...
// Prints JSON: the header, the metadata, and per tile its layer names, feature counts and feature ids.
import { open } from "node:fs/promises";
import { VectorTile } from "@mapbox/vector-tile";
import Pbf from "pbf";
import { PMTiles } from "pmtiles";

// A pmtiles Source over a file on disk: range reads with a file handle.
class NodeFileSource {
  constructor(path) {
    this.path = path;
    this.handle = null;
  }

  getKey() {
    return this.path;
  }

  async getBytes(offset, length) {
    this.handle ??= await open(this.path, "r");
    const buf = Buffer.alloc(length);
    const { bytesRead } = await this.handle.read(buf, 0, length, offset);
    const data = buf.buffer.slice(buf.byteOffset, buf.byteOffset + bytesRead);
    return { data };
  }

  async close() {
    await this.handle?.close();
  }
}

const [path, ...tiles] = process.argv.slice(2);
const source = new NodeFileSource(path);
const archive = new PMTiles(source);
const header = await archive.getHeader();
const metadata = await archive.getMetadata();
const out = { header, metadata, tiles: [] };
for (const zxy of tiles) {
  const [z, x, y] = zxy.split("/").map(Number);
  const resp = await archive.getZxy(z, x, y); // decompressed by the reader (header.tileCompression)
  if (!resp) {
    out.tiles.push({ tile: zxy, missing: true });
    continue;
  }
  const vt = new VectorTile(new Pbf(new Uint8Array(resp.data)));
  const layers = {};
  for (const [name, layer] of Object.entries(vt.layers)) {
    const ids = [];
    for (let i = 0; i < layer.length; i++) ids.push(layer.feature(i).id);
    layers[name] = { extent: layer.extent, features: layer.length, ids };
  }
  out.tiles.push({ tile: zxy, layers: Object.keys(vt.layers), detail: layers });
}
await source.close();
process.stdout.write(JSON.stringify(out));
