// Morph tiles (docs/morph-tiles.md): decode one tile once into flat arrays, then give the layer `contours`
// as drawn at any zoom inside its level, as features for the MVT encoder. Pure functions, no state.

import {readVectorTile} from './protobuf.js';
import {fadeAt, levelFraction, morphWeight, tAt, tSamples} from './tinterp.js';
import {encodeMvt, GEOM_LINESTRING} from './mvt.js';

export const START_LAYER = 'contours';
export const END_LAYER = 'contours_end';

/** Flatten a feature's geometry into one Float64Array of x, y and the start offset of each part. */
function flatten(rings) {
  let n = 0;
  for (const ring of rings) n += ring.length;
  const xy = new Float64Array(n * 2);
  const offsets = new Uint32Array(rings.length + 1);
  let i = 0;
  rings.forEach((ring, r) => {
    offsets[r] = i;
    for (const p of ring) {
      xy[i++] = p.x;
      xy[i++] = p.y;
    }
  });
  offsets[rings.length] = i;
  return {xy, offsets};
}

function sameShape(a, b) {
  if (a.offsets.length !== b.offsets.length) return false;
  for (let i = 0; i < a.offsets.length; i++) if (a.offsets[i] !== b.offsets[i]) return false;
  return true;
}

/**
 * Decode a morph tile (uncompressed MVT bytes) into
 * {extent, features: [{id, properties, samples, minZoom, start: {xy, offsets}, end: {xy, offsets} | null}],
 *  mismatched}. `end` is null (the feature does not move) when `contours_end` has no feature of that id with
 * the same parts and point counts; `mismatched` counts those. A tile without `contours_end` is a plain tile:
 * every feature keeps its geometry. Empty input gives an empty tile.
 * @param {ArrayBuffer | Uint8Array} bytes
 */
export function decodeMorphTile(bytes) {
  const data = bytes instanceof Uint8Array ? bytes : new Uint8Array(bytes ?? new ArrayBuffer(0));
  if (!data.byteLength) return {extent: 4096, features: [], mismatched: 0};
  const vt = readVectorTile(data);
  const start = vt.layers[START_LAYER];
  if (!start) return {extent: 4096, features: [], mismatched: 0};
  const endLayer = vt.layers[END_LAYER];
  const ends = [];
  const endById = new Map();
  if (endLayer) {
    for (let i = 0; i < endLayer.length; i++) {
      const f = endLayer.feature(i);
      ends.push(f);
      if (f.id !== undefined) endById.set(f.id, f);
    }
  }
  const scaleEnd = endLayer && endLayer.extent !== start.extent ? start.extent / endLayer.extent : 1;
  const features = [];
  let mismatched = 0;
  for (let i = 0; i < start.length; i++) {
    const f = start.feature(i);
    if (f.type !== GEOM_LINESTRING) continue;
    const s = flatten(f.loadGeometry());
    let end = null;
    if (endLayer) {
      // Same order as `contours` by the format; fall back to the id when the order differs.
      let ef = ends[i];
      if (!ef || ef.id !== f.id) ef = endById.get(f.id);
      if (ef) {
        const e = flatten(ef.loadGeometry());
        if (scaleEnd !== 1) for (let k = 0; k < e.xy.length; k++) e.xy[k] *= scaleEnd;
        if (sameShape(s, e)) end = e;
      }
      if (!end) mismatched += 1;
    }
    const props = {...f.properties};
    const minZoom = typeof props.min_zoom === 'number' ? props.min_zoom : null;
    features.push({id: f.id, properties: props, samples: tSamples(props), minZoom, start: s, end});
  }
  return {extent: start.extent, features, mismatched};
}

/** The properties of the drawn feature: `t` is t at the drawn zoom; the t samples are dropped unless kept. */
function drawnProperties(feature, t, fade, keepSamples) {
  const out = {};
  for (const [key, value] of Object.entries(feature.properties)) {
    if (!keepSamples && /^t\d+$/.test(key)) continue;
    out[key] = value;
  }
  if (t !== null) out.t = Math.round(t * 1e4) / 1e4;
  out.morph_fade = fade;
  return out;
}

/**
 * The features of layer `contours` drawn at map zoom `zoom` from a decoded morph tile of zoom z.
 * Options: scale (output units per tile unit, default 1), fadeSpan (zoom levels over which a contour that
 * appears at its min_zoom fades in, default 0: shown at once), keepSamples (keep t1 ... tN, default false).
 * Each feature is {id, type: 2, parts: [Float64Array x, y ...], properties}; properties gain `morph_fade`
 * (0 ... 1) and have `t` set to the interpolated t. Contours with zoom <= min_zoom are left out.
 */
export function interpolateFeatures(tile, z, zoom, {scale = 1, fadeSpan = 0, keepSamples = false} = {}) {
  const f = levelFraction(zoom, z);
  const out = [];
  for (const feature of tile.features) {
    const fade = fadeAt(feature.minZoom, zoom, fadeSpan);
    if (fade <= 0) continue;
    const samples = feature.samples;
    const w = samples && feature.end ? morphWeight(samples, f) : 0;
    const {xy, offsets} = feature.start;
    const exy = feature.end?.xy;
    const parts = [];
    for (let p = 0; p + 1 < offsets.length; p++) {
      const a = offsets[p];
      const b = offsets[p + 1];
      const part = new Float64Array(b - a);
      for (let i = a; i < b; i++) {
        const v = w === 0 ? xy[i] : xy[i] + w * (exy[i] - xy[i]);
        part[i - a] = v * scale;
      }
      parts.push(part);
    }
    const t = samples ? tAt(samples, f) : null;
    out.push({id: feature.id, type: GEOM_LINESTRING, parts, properties: drawnProperties(feature, t, fade, keepSamples)});
  }
  return out;
}

/**
 * One vector tile with layer `contours` as drawn at `zoom` (see interpolateFeatures), at extent
 * tile.extent * scale (options.scale: 2 gives MapLibre's own internal precision for 4096-unit tiles).
 * @returns {Uint8Array}
 */
export function renderMorphTile(tile, z, zoom, options = {}) {
  const scale = options.scale ?? 1;
  const features = interpolateFeatures(tile, z, zoom, options);
  return encodeMvt([{name: options.layerName ?? START_LAYER, extent: Math.round(tile.extent * scale), features}]);
}
