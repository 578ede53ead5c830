// Test helpers: build morph tiles with the plugin's own encoder, read tiles back with @mapbox/vector-tile.
import {VectorTile} from '@mapbox/vector-tile';
import {PbfReader} from 'pbf';
import {encodeMvt} from '../src/mvt.js';

/** Decode MVT bytes: {layerName: {extent, features: [{id, type, properties, rings: [[[x, y], ...]]}]}}. */
export function readTile(bytes) {
  const vt = new VectorTile(new PbfReader(bytes));
  const out = {};
  for (const [name, layer] of Object.entries(vt.layers)) {
    const features = [];
    for (let i = 0; i < layer.length; i++) {
      const f = layer.feature(i);
      features.push({
        id: f.id,
        type: f.type,
        properties: {...f.properties},
        rings: f.loadGeometry().map((ring) => ring.map((p) => [p.x, p.y])),
      });
    }
    out[name] = {extent: layer.extent, features};
  }
  return out;
}

/**
 * A morph tile: each contour {id, start: [[x, y...]...parts], end: same shape, props}, the t samples in
 * props (t, t1 ... t8).
 */
export function morphTileBytes(contours, extent = 4096) {
  return encodeMvt([
    {
      name: 'contours',
      extent,
      features: contours.map((c) => ({id: c.id, type: 2, parts: c.start, properties: c.props})),
    },
    {
      name: 'contours_end',
      extent,
      features: contours.map((c) => ({id: c.id, type: 2, parts: c.end, properties: {}})),
    },
  ]);
}

/** t samples as properties: t = ts[0], tk = ts[k]. */
export function tProps(ts, extra = {}) {
  const props = {...extra, t: ts[0]};
  ts.slice(1).forEach((v, i) => (props[`t${i + 1}`] = v));
  return props;
}
