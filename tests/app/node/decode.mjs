// Decode MVT files with @mapbox/vector-tile (MapLibre's parser) and print what the tests check, as JSON.
// Usage: node decode.mjs z/x/y=path.mvt ...
import { readFileSync } from "node:fs";
import { VectorTile } from "@mapbox/vector-tile";
import Pbf from "pbf";

const out = [];
for (const arg of process.argv.slice(2)) {
  const [zxy, path] = arg.split("=");
  const [z, x, y] = zxy.split("/").map(Number);
  const tile = new VectorTile(new Pbf(readFileSync(path)));
  const layer = tile.layers.contours;
  const features = [];
  for (let i = 0; i < layer.length; i++) {
    const f = layer.feature(i);
    features.push({
      id: f.id,
      type: f.type,
      extent: f.extent,
      properties: f.properties,
      geometry: f.loadGeometry().map((ring) => ring.map((p) => [p.x, p.y])),
      lonlat: f.toGeoJSON(x, y, z).geometry,
    });
  }
  out.push({ tile: zxy, layers: Object.keys(tile.layers), version: layer.version, extent: layer.extent, features });
}
process.stdout.write(JSON.stringify(out));
