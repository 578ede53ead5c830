// The `ccsm://` protocol: MapLibre asks for `ccsm://<key>/{z}/{x}/{y}`; we look up which TileJSON template,
// morph zoom, method and pinned t that source stands for, and fetch the real tile with an AbortController that
// MapLibre fires when the tile is no longer wanted (its source removed, or the tile scrolled away).

import {addProtocol} from 'maplibre-gl';
import {morphZoomForTile} from './scale.js';
import {buildTileUrl, ccsmTemplate, parseCcsmUrl} from './tileurl.js';

const configs = new Map();
let nextKey = 1;

/** Listeners told about every tile fetch (for the "requests in flight" readout). */
const listeners = new Set();
let inFlight = 0;

function notify() {
  for (const fn of listeners) fn(inFlight);
}

export function onTileActivity(fn) {
  listeners.add(fn);
}

/** Register one source's parameters; returns the `tiles` URL for MapLibre. */
export function registerSource({template, q, method, t}) {
  const key = `s${nextKey++}`;
  configs.set(key, {template, q, method, t});
  return {key, url: ccsmTemplate(key)};
}

export function unregisterSource(key) {
  configs.delete(key);
}

async function loadTile(params, abortController) {
  const {key, z: zs, x: xs, y: ys} = parseCcsmUrl(params.url);
  const cfg = configs.get(key);
  // A source removed while MapLibre still asks: answer empty, the tile is about to be dropped.
  if (!cfg) return {data: new ArrayBuffer(0)};
  const z = Number(zs);
  const query = {zoom: morphZoomForTile(cfg.q, z), method: cfg.method, t: cfg.t};
  const url = buildTileUrl(cfg.template, zs, xs, ys, query, window.location.href);
  inFlight += 1;
  notify();
  try {
    const response = await fetch(url, {signal: abortController.signal});
    if (response.status === 204) return {data: new ArrayBuffer(0)};
    if (!response.ok) {
      let detail = '';
      try {
        const body = await response.json();
        detail = typeof body.detail === 'string' ? body.detail : JSON.stringify(body.detail);
      } catch {
        detail = response.statusText;
      }
      throw new Error(`tile ${z}/${xs}/${ys} failed (HTTP ${response.status}): ${detail}`);
    }
    return {data: await response.arrayBuffer()};
  } finally {
    inFlight -= 1;
    notify();
  }
}

let installed = false;

export function installProtocol() {
  if (installed) return;
  addProtocol('ccsm', loadTile);
  installed = true;
}
