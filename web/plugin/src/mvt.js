// A small Mapbox Vector Tile (spec 2.1) encoder: what the plugin needs to hand MapLibre one interpolated tile.
// The protobuf wire format is written with protobuf.js's ProtoWriter; the MVT messages are laid out here.
//
// Input: layers [{name, extent, features}], each feature {id?, type, parts, properties}:
//   type 1 (POINT), 2 (LINESTRING) or 3 (POLYGON);
//   parts: an array of parts, each a flat [x0, y0, x1, y1, ...] (any array-like of numbers) in tile units;
//          coordinates are rounded to integers here; for polygons each part is one ring, not closed (the
//          encoder writes ClosePath), wound as the spec wants (the caller's business);
//   properties: {key: string | number | boolean}; null/undefined values are left out.
// Line parts that shrink below two distinct points after rounding are dropped, and so is a feature left
// without parts.

import {ProtoWriter} from './protobuf.js';

export const GEOM_POINT = 1;
export const GEOM_LINESTRING = 2;
export const GEOM_POLYGON = 3;

const CMD_MOVE_TO = 1;
const CMD_LINE_TO = 2;
const CMD_CLOSE_PATH = 7;

const command = (id, count) => (id & 0x7) | (count << 3);
const zigzag = (n) => (n << 1) ^ (n >> 31);

/**
 * The geometry command stream of one feature, or null when nothing drawable is left.
 * @param {number} type
 * @param {ArrayLike<ArrayLike<number>>} parts
 * @returns {number[] | null}
 */
export function encodeGeometry(type, parts) {
  const out = [];
  let cx = 0;
  let cy = 0;
  if (type === GEOM_POINT) {
    const pts = [];
    for (const part of parts) for (let i = 0; i + 1 < part.length; i += 2) pts.push(Math.round(part[i]), Math.round(part[i + 1]));
    if (!pts.length) return null;
    out.push(command(CMD_MOVE_TO, pts.length / 2));
    for (let i = 0; i < pts.length; i += 2) {
      out.push(zigzag(pts[i] - cx), zigzag(pts[i + 1] - cy));
      cx = pts[i];
      cy = pts[i + 1];
    }
    return out;
  }
  const minPoints = type === GEOM_POLYGON ? 3 : 2;
  for (const part of parts) {
    // Round, then drop points that repeat the previous one.
    const xs = [];
    const ys = [];
    for (let i = 0; i + 1 < part.length; i += 2) {
      const x = Math.round(part[i]);
      const y = Math.round(part[i + 1]);
      const last = xs.length - 1;
      if (last >= 0 && xs[last] === x && ys[last] === y) continue;
      xs.push(x);
      ys.push(y);
    }
    if (type === GEOM_POLYGON && xs.length > 1 && xs[0] === xs[xs.length - 1] && ys[0] === ys[ys.length - 1]) {
      xs.pop();
      ys.pop();
    }
    if (xs.length < minPoints) continue;
    out.push(command(CMD_MOVE_TO, 1), zigzag(xs[0] - cx), zigzag(ys[0] - cy));
    cx = xs[0];
    cy = ys[0];
    out.push(command(CMD_LINE_TO, xs.length - 1));
    for (let i = 1; i < xs.length; i++) {
      out.push(zigzag(xs[i] - cx), zigzag(ys[i] - cy));
      cx = xs[i];
      cy = ys[i];
    }
    if (type === GEOM_POLYGON) out.push(command(CMD_CLOSE_PATH, 1));
  }
  return out.length ? out : null;
}

/** Key of a property value in a layer's value table: the same value of the same kind is stored once. */
function valueKey(value) {
  if (typeof value === 'string') return `s:${value}`;
  if (typeof value === 'boolean') return `b:${value}`;
  return `n:${value}`;
}

function writeValue(value, pbf) {
  if (typeof value === 'string') pbf.writeStringField(1, value);
  else if (typeof value === 'boolean') pbf.writeBooleanField(7, value);
  else if (Number.isInteger(value) && Math.abs(value) <= 2 ** 31 - 1) {
    if (value >= 0) pbf.writeVarintField(5, value); // uint_value
    else pbf.writeSVarintField(6, value); // sint_value
  } else pbf.writeDoubleField(3, value);
}

function writeFeature(f, pbf) {
  if (f.id !== undefined && f.id !== null) pbf.writeVarintField(1, f.id);
  pbf.writePackedVarint(2, f.tags);
  pbf.writeVarintField(3, f.type);
  pbf.writePackedVarint(4, f.geometry);
}

function writeLayer(layer, pbf) {
  pbf.writeVarintField(15, 2); // version
  pbf.writeStringField(1, layer.name);
  for (const f of layer.features) pbf.writeMessage(2, writeFeature, f);
  for (const k of layer.keys) pbf.writeStringField(3, k);
  for (const v of layer.values) pbf.writeMessage(4, writeValue, v);
  pbf.writeVarintField(5, layer.extent);
}

/** Lay one layer out: key and value tables, tags and geometry commands of each feature. */
function prepareLayer({name, extent = 4096, features}) {
  const keys = [];
  const keyIndex = new Map();
  const values = [];
  const valueIndex = new Map();
  const out = [];
  for (const feature of features) {
    const type = feature.type ?? GEOM_LINESTRING;
    const geometry = encodeGeometry(type, feature.parts);
    if (!geometry) continue;
    const tags = [];
    for (const [key, value] of Object.entries(feature.properties ?? {})) {
      if (value === null || value === undefined) continue;
      if (typeof value === 'number' && !Number.isFinite(value)) continue;
      const v = typeof value === 'object' ? JSON.stringify(value) : value;
      let ki = keyIndex.get(key);
      if (ki === undefined) {
        ki = keys.push(key) - 1;
        keyIndex.set(key, ki);
      }
      const vk = valueKey(v);
      let vi = valueIndex.get(vk);
      if (vi === undefined) {
        vi = values.push(v) - 1;
        valueIndex.set(vk, vi);
      }
      tags.push(ki, vi);
    }
    const id = Number.isSafeInteger(feature.id) && feature.id >= 0 ? feature.id : undefined;
    out.push({id, tags, type, geometry});
  }
  return {name, extent, keys, values, features: out};
}

/**
 * Encode layers as one vector tile.
 * @param {Array<{name: string, extent?: number, features: Array<object>}>} layers
 * @returns {Uint8Array}
 */
export function encodeMvt(layers) {
  const pbf = new ProtoWriter();
  for (const layer of layers) pbf.writeMessage(3, writeLayer, prepareLayer(layer));
  return pbf.finish();
}
