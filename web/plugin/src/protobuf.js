// The protobuf wire format as far as vector tiles need it, with no imports: the worker (morph-worker.js) loads
// this module graph, and a module worker does not see the page's import map, so it can hold no bare specifiers.
// ProtoWriter writes what mvt.js encodes; readVectorTile reads layers and features as @mapbox/vector-tile does.

const VARINT = 0;
const FIXED64 = 1;
const BYTES = 2;
const FIXED32 = 5;

const encoder = new TextEncoder();
const decoder = new TextDecoder();

/** A growing byte buffer with the field writers mvt.js uses. */
export class ProtoWriter {
  /** @param {number} [size]  the first buffer's size (it grows as needed) */
  constructor(size = 16 * 1024) {
    this.buf = new Uint8Array(size);
    this.pos = 0;
    this.view = new DataView(this.buf.buffer);
  }

  _room(n) {
    if (this.pos + n <= this.buf.length) return;
    let size = this.buf.length * 2;
    while (size < this.pos + n) size *= 2;
    const next = new Uint8Array(size);
    next.set(this.buf.subarray(0, this.pos));
    this.buf = next;
    this.view = new DataView(next.buffer);
  }

  writeVarint(value) {
    this._room(10);
    let v = value;
    if (v < 0 || v > 0xfffffff) {
      // Beyond 28 bits: arithmetic, not bit operations (which are 32-bit signed in JS).
      if (v < 0) v += 2 ** 64;
      while (v >= 0x80) {
        this.buf[this.pos++] = (v % 0x80) | 0x80;
        v = Math.floor(v / 0x80);
      }
      this.buf[this.pos++] = v;
      return;
    }
    while (v >= 0x80) {
      this.buf[this.pos++] = (v & 0x7f) | 0x80;
      v >>>= 7;
    }
    this.buf[this.pos++] = v;
  }

  _tag(field, type) {
    this.writeVarint((field << 3) | type);
  }

  writeVarintField(field, value) {
    this._tag(field, VARINT);
    this.writeVarint(value);
  }

  writeSVarintField(field, value) {
    this._tag(field, VARINT);
    this.writeVarint(value < 0 ? -value * 2 - 1 : value * 2);
  }

  writeBooleanField(field, value) {
    this.writeVarintField(field, value ? 1 : 0);
  }

  writeDoubleField(field, value) {
    this._tag(field, FIXED64);
    this._room(8);
    this.view.setFloat64(this.pos, value, true);
    this.pos += 8;
  }

  _bytes(field, bytes) {
    this._tag(field, BYTES);
    this.writeVarint(bytes.length);
    this._room(bytes.length);
    this.buf.set(bytes, this.pos);
    this.pos += bytes.length;
  }

  writeStringField(field, value) {
    this._bytes(field, encoder.encode(value));
  }

  /** Field `field` holding the message that fn(obj, writer) writes. */
  writeMessage(field, fn, obj) {
    const inner = new ProtoWriter(256);
    fn(obj, inner);
    this._bytes(field, inner.finish());
  }

  writePackedVarint(field, values) {
    if (!values.length) return;
    const inner = new ProtoWriter(values.length * 2 + 8);
    for (const v of values) inner.writeVarint(v);
    this._bytes(field, inner.finish());
  }

  finish() {
    return this.buf.slice(0, this.pos);
  }
}

/** A reader over bytes: varints, lengths and skips. */
class ProtoReader {
  constructor(bytes, pos = 0, end = bytes.length) {
    this.buf = bytes;
    this.pos = pos;
    this.end = end;
  }

  varint() {
    let result = 0;
    let shift = 1;
    for (;;) {
      const b = this.buf[this.pos++];
      result += (b & 0x7f) * shift;
      if (b < 0x80) return result;
      shift *= 128;
    }
  }

  skip(type) {
    if (type === VARINT) while (this.buf[this.pos++] >= 0x80);
    else if (type === FIXED64) this.pos += 8;
    else if (type === FIXED32) this.pos += 4;
    else if (type === BYTES) this.pos += this.varint();
    else throw new Error(`protobuf: wire type ${type} not supported`);
  }

  /** The sub-reader of a length-delimited field. */
  message() {
    const len = this.varint();
    const sub = new ProtoReader(this.buf, this.pos, this.pos + len);
    this.pos += len;
    return sub;
  }

  string() {
    const sub = this.message();
    return decoder.decode(this.buf.subarray(sub.pos, sub.end));
  }

  packed() {
    const sub = this.message();
    const out = [];
    while (sub.pos < sub.end) out.push(sub.varint());
    return out;
  }
}

function readValue(r) {
  const view = new DataView(r.buf.buffer, r.buf.byteOffset);
  let value = null;
  while (r.pos < r.end) {
    const tag = r.varint();
    const field = tag >> 3;
    if (field === 1) value = r.string();
    else if (field === 2) value = view.getFloat32((r.pos += 4) - 4, true);
    else if (field === 3) value = view.getFloat64((r.pos += 8) - 8, true);
    else if (field === 4 || field === 5) value = r.varint(); // int64 / uint64 (non-negative here)
    else if (field === 6) {
      const z = r.varint();
      value = z % 2 ? -(z + 1) / 2 : z / 2;
    } else if (field === 7) value = Boolean(r.varint());
    else r.skip(tag & 7);
  }
  return value;
}

/** Geometry commands to parts of points [{x, y}], as VectorTileFeature.loadGeometry gives them. */
function loadGeometry(commands) {
  const parts = [];
  let part = null;
  let x = 0;
  let y = 0;
  const zz = (n) => (n >>> 1) ^ -(n & 1);
  for (let i = 0; i < commands.length; ) {
    const id = commands[i] & 7;
    const count = commands[i] >>> 3;
    i += 1;
    if (id === 7) {
      if (part?.length) part.push({x: part[0].x, y: part[0].y});
      continue;
    }
    for (let k = 0; k < count; k++) {
      x += zz(commands[i++]);
      y += zz(commands[i++]);
      if (id === 1) {
        part = [];
        parts.push(part);
      }
      part.push({x, y});
    }
  }
  return parts;
}

function readFeature(r, keys, values) {
  const f = {id: undefined, type: 0, tags: [], geometry: []};
  while (r.pos < r.end) {
    const tag = r.varint();
    const field = tag >> 3;
    if (field === 1) f.id = r.varint();
    else if (field === 2) f.tags = r.packed();
    else if (field === 3) f.type = r.varint();
    else if (field === 4) f.geometry = r.packed();
    else r.skip(tag & 7);
  }
  const properties = {};
  for (let i = 0; i + 1 < f.tags.length; i += 2) properties[keys[f.tags[i]]] = values[f.tags[i + 1]];
  const commands = f.geometry;
  return {id: f.id, type: f.type, properties, loadGeometry: () => loadGeometry(commands)};
}

function readLayer(r) {
  const layer = {name: '', extent: 4096, keys: [], values: [], raw: []};
  while (r.pos < r.end) {
    const tag = r.varint();
    const field = tag >> 3;
    if (field === 1) layer.name = r.string();
    else if (field === 2) layer.raw.push(r.message());
    else if (field === 3) layer.keys.push(r.string());
    else if (field === 4) layer.values.push(readValue(r.message()));
    else if (field === 5) layer.extent = r.varint();
    else r.skip(tag & 7);
  }
  const features = layer.raw.map((m) => readFeature(m, layer.keys, layer.values));
  return {name: layer.name, extent: layer.extent, length: features.length, feature: (i) => features[i]};
}

/**
 * The layers of a vector tile by name: {extent, length, feature(i)}, each feature {id, type, properties,
 * loadGeometry()} (parts of {x, y} points; a closed ring repeats its first point), as @mapbox/vector-tile reads it.
 * @param {Uint8Array} bytes
 */
export function readVectorTile(bytes) {
  const r = new ProtoReader(bytes);
  const layers = {};
  while (r.pos < r.end) {
    const tag = r.varint();
    if (tag >> 3 === 3) {
      const layer = readLayer(r.message());
      layers[layer.name] = layer;
    } else r.skip(tag & 7);
  }
  return {layers};
}
