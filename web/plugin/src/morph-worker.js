// The plugin's tile work off the main thread: decoding morph tiles, and drawing a step of one (interpolation
// and MVT encoding). createRenderer() starts this file as a module worker, which answers WorkerRenderer's
// messages; where there is no Worker (node) or it fails to start, the same MorphRenderer runs in the page.
// Tile bytes go to the worker and drawn tiles come back as transferred ArrayBuffers (no copies).
//
// After a step is drawn the next steps in the zoom direction are drawn ahead, while the worker is idle, so
// that a request during a gesture is usually answered with bytes already encoded.

import {decodeMorphTile, renderMorphTile} from './morphtile.js';

/** Steps drawn ahead of the last one asked for, per tile. */
const AHEAD = 2;
/** Drawn-ahead tiles kept (a view of a dozen tiles, a few steps each). */
const DRAWN_KEPT = 96;

export class MorphRenderer {
  /**
   * @param {{capacity?: number, ahead?: number, schedule?: (fn: () => void) => void}} options  capacity:
   *   decoded tiles kept; ahead: steps drawn in advance (0: none); schedule: how idle work is queued
   */
  constructor({capacity = 192, ahead = 0, schedule = (fn) => setTimeout(fn, 0)} = {}) {
    this.capacity = Math.max(1, capacity);
    this.ahead = ahead;
    this.schedule = schedule;
    this.tiles = new Map();
    this.drawn = new Map();
    this.queue = [];
    this.queued = false;
    this.renders = 0;
  }

  /** Decode and keep tile `key` (its bytes); returns whether it has no features. */
  add(key, bytes) {
    const tile = decodeMorphTile(bytes);
    this.tiles.delete(key);
    this.tiles.set(key, tile);
    while (this.tiles.size > this.capacity) this._drop(this.tiles.keys().next().value);
    return {empty: !tile.features.length};
  }

  /** The decoded tile `key`, or null when it is not kept. */
  get(key) {
    return this.tiles.get(key) ?? null;
  }

  /**
   * The MVT bytes of tile `key` (of zoom z) drawn at step `step`, or null when the tile is not kept.
   * @param {string} key
   * @param {{z: number, step: number, stepsPerZoom: number, direction?: number, options: object}} request
   */
  render(key, {z, step, stepsPerZoom, direction = 1, options}) {
    const tile = this.tiles.get(key);
    if (!tile) return null;
    this.tiles.delete(key); // the newest end of the least-recently-used order
    this.tiles.set(key, tile);
    const id = `${key}@${step}`;
    let bytes = this.drawn.get(id);
    if (bytes) this.drawn.delete(id);
    else bytes = this._draw(tile, z, step, stepsPerZoom, options);
    if (this.ahead > 0) this._drawAhead(key, {z, step, stepsPerZoom, direction, options});
    return bytes;
  }

  _draw(tile, z, step, stepsPerZoom, options) {
    this.renders += 1;
    return renderMorphTile(tile, z, step / stepsPerZoom, options);
  }

  _drawAhead(key, {z, step, stepsPerZoom, direction, options}) {
    const sign = direction < 0 ? -1 : 1;
    for (let k = 1; k <= this.ahead; k++) this.queue.push({key, z, step: step + sign * k, stepsPerZoom, options});
    // Only the newest requests are worth drawing ahead for.
    if (this.queue.length > 64) this.queue.splice(0, this.queue.length - 64);
    if (this.queued) return;
    this.queued = true;
    this.schedule(() => this._runQueue());
  }

  _runQueue() {
    const job = this.queue.shift();
    if (!job) {
      this.queued = false;
      return;
    }
    const tile = this.tiles.get(job.key);
    const id = `${job.key}@${job.step}`;
    if (tile && !this.drawn.has(id)) {
      this.drawn.set(id, this._draw(tile, job.z, job.step, job.stepsPerZoom, job.options));
      while (this.drawn.size > DRAWN_KEPT) this.drawn.delete(this.drawn.keys().next().value);
    }
    // One job per task, so that requests that arrive meanwhile are answered first.
    this.schedule(() => this._runQueue());
  }

  _drop(key) {
    this.tiles.delete(key);
    for (const id of this.drawn.keys()) if (id.startsWith(`${key}@`)) this.drawn.delete(id);
  }
}

/** Answer WorkerRenderer's messages: {id, op: 'init' | 'add' | 'get' | 'render', ...}. */
function serve(scope) {
  let renderer = new MorphRenderer({ahead: AHEAD});
  scope.onmessage = ({data}) => {
    const {id, op} = data;
    try {
      if (op === 'init') {
        renderer = new MorphRenderer({capacity: data.capacity, ahead: data.ahead ?? AHEAD});
        scope.postMessage({id, result: true});
      } else if (op === 'add') {
        scope.postMessage({id, result: renderer.add(data.key, data.bytes)});
      } else if (op === 'get') {
        scope.postMessage({id, result: renderer.get(data.key)});
      } else if (op === 'render') {
        const bytes = renderer.render(data.key, data.request);
        const buffer = bytes ? toBuffer(bytes) : null;
        scope.postMessage({id, result: buffer}, buffer ? [buffer] : []);
      } else {
        throw new Error(`ccsm-morph worker: unknown message ${op}`);
      }
    } catch (err) {
      scope.postMessage({id, error: err?.message ?? String(err)});
    }
  };
  scope.postMessage({ready: true});
}

/** The bytes as an ArrayBuffer of their own (transferable without taking a shared buffer along). */
export function toBuffer(bytes) {
  if (bytes.byteOffset === 0 && bytes.byteLength === bytes.buffer.byteLength) return bytes.buffer;
  return bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
}

/** The page's side of the worker: each call posts a message and resolves with its answer. */
class WorkerRenderer {
  constructor(worker) {
    this.mode = 'worker';
    this.worker = worker;
    this.calls = new Map();
    this.next = 0;
    worker.onmessage = ({data}) => {
      const call = this.calls.get(data.id);
      if (!call) return;
      this.calls.delete(data.id);
      if (data.error) call.reject(new Error(data.error));
      else call.resolve(data.result);
    };
  }

  _call(message, transfer = []) {
    const id = ++this.next;
    return new Promise((resolve, reject) => {
      this.calls.set(id, {resolve, reject});
      this.worker.postMessage({...message, id}, transfer);
    });
  }

  init(capacity) {
    return this._call({op: 'init', capacity});
  }

  add(key, bytes) {
    const buffer = toBuffer(bytes);
    return this._call({op: 'add', key, bytes: buffer}, [buffer]);
  }

  get(key) {
    return this._call({op: 'get', key});
  }

  render(key, request) {
    return this._call({op: 'render', key, request});
  }

  terminate() {
    this.worker.terminate();
  }
}

/** MorphRenderer in the page's thread, behind the same promise-returning calls (nothing drawn ahead). */
class LocalRenderer {
  constructor(capacity) {
    this.mode = 'local';
    this.renderer = new MorphRenderer({capacity});
  }

  async add(key, bytes) {
    return this.renderer.add(key, bytes);
  }

  async get(key) {
    return this.renderer.get(key);
  }

  async render(key, request) {
    const bytes = this.renderer.render(key, request);
    return bytes ? toBuffer(bytes) : null;
  }

  terminate() {}
}

/**
 * A renderer for one CcsmMorph: this file as a module worker when `useWorker` and the platform allows,
 * else in the page. Resolves once the worker has loaded (its imports resolved) or failed to.
 * @param {{capacity: number, useWorker?: boolean}} options
 */
export async function createRenderer({capacity, useWorker = true}) {
  if (!useWorker || typeof globalThis.Worker !== 'function') return new LocalRenderer(capacity);
  let worker;
  try {
    worker = new Worker(new URL('./morph-worker.js', import.meta.url), {type: 'module'});
  } catch {
    return new LocalRenderer(capacity);
  }
  const started = await new Promise((resolve) => {
    worker.onmessage = ({data}) => resolve(Boolean(data?.ready));
    worker.onerror = (event) => {
      event.preventDefault?.();
      resolve(false);
    };
  });
  if (!started) {
    worker.terminate();
    return new LocalRenderer(capacity);
  }
  worker.onerror = null;
  const renderer = new WorkerRenderer(worker);
  await renderer.init(capacity);
  return renderer;
}

// In a dedicated worker (not in the page, not in node): serve the plugin.
if (typeof globalThis.WorkerGlobalScope === 'function' && globalThis instanceof globalThis.WorkerGlobalScope) {
  serve(globalThis);
}
