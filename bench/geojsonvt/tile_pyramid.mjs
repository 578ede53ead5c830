// Tile a GeoJSON with geojson-vt (per-zoom Douglas-Peucker, as MapLibre does for GeoJSON sources) and
// encode each tile with vt-pbf; print the times as JSON.
// Usage: node tile_pyramid.mjs data.geojson tiles.json   (tiles.json: [[z, x, y], ...])
import { readFileSync } from "node:fs";
import geojsonvt from "geojson-vt";
import vtpbf from "vt-pbf";

const [dataPath, tilesPath] = process.argv.slice(2);
const tiles = JSON.parse(readFileSync(tilesPath, "utf8"));
const t0 = performance.now();
const data = JSON.parse(readFileSync(dataPath, "utf8"));
const t1 = performance.now();
const maxZoom = Math.max(...tiles.map((t) => t[0]));
const index = geojsonvt(data, { maxZoom, indexMaxZoom: 5, indexMaxPoints: 100000, tolerance: 3, extent: 4096, buffer: 64 });
const t2 = performance.now();
let nonEmpty = 0;
let bytes = 0;
for (const [z, x, y] of tiles) {
  const tile = index.getTile(z, x, y);
  if (tile && tile.features.length) {
    const buf = vtpbf.fromGeojsonVt({ contours: tile }, { version: 2, extent: 4096 });
    bytes += buf.length;
    nonEmpty++;
  }
}
const t3 = performance.now();
process.stdout.write(JSON.stringify({
  parse_ms: t1 - t0, index_ms: t2 - t1, tiles_ms: t3 - t2, total_ms: t3 - t1,
  tiles: tiles.length, non_empty: nonEmpty, bytes,
}));
