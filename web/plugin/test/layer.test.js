// MorphLayer's pacing of step loads (layer.js): after a swap the next step waits until the last load took at
// most `loadShare` of the time, and a camera that stops during the pause still gets its step. A map stand-in
// records what the layer asks of MapLibre; the clock is the test's.
import assert from 'node:assert/strict';
import {test} from 'node:test';
import {MorphLayer} from '../src/layer.js';

class StandInMap {
  constructor(zoom) {
    this.zoom = zoom;
    this.handlers = {};
    this.sources = {};
    this.layers = new Set();
    this.loaded = {};
    this.setTilesCalls = [];
    this.repaints = 0;
  }
  on(name, fn) {
    (this.handlers[name] ??= []).push(fn);
  }
  off(name, fn) {
    this.handlers[name] = (this.handlers[name] ?? []).filter((f) => f !== fn);
  }
  fire(name, event = {}) {
    for (const fn of this.handlers[name] ?? []) fn(event);
  }
  getZoom() {
    return this.zoom;
  }
  addSource(id, spec) {
    const calls = this.setTilesCalls;
    this.sources[id] = {spec, setTiles: (tiles) => calls.push({id, url: tiles[0]})};
    this.loaded[id] = false;
  }
  getSource(id) {
    return this.sources[id];
  }
  removeSource(id) {
    delete this.sources[id];
  }
  addLayer(layer) {
    this.layers.add(layer.id);
  }
  getLayer(id) {
    return this.layers.has(id) ? {id} : undefined;
  }
  removeLayer(id) {
    this.layers.delete(id);
  }
  setPaintProperty() {}
  isSourceLoaded(id) {
    return this.loaded[id];
  }
  triggerRepaint() {
    this.repaints += 1;
  }
}

const morph = {
  stepsPerZoom: 32,
  metadata: () => Promise.resolve({minzoom: 0, maxzoom: 14}),
  tileUrl: (step) => `ccsm://step${step}/{z}/{x}/{y}`,
};

/** A layer on a stand-in map at `zoom`, its first buffer loaded, and a clock the test moves. */
async function layerAt(zoom, loadShare) {
  const map = new StandInMap(zoom);
  const clock = {ms: 0};
  const layer = new MorphLayer(morph, map, {layers: [{id: 'lines', type: 'line'}], loadShare, now: () => clock.ms});
  await layer.ready;
  map.loaded['ccsm-morph-a'] = true;
  map.fire('render');
  return {map, clock, layer};
}

/** Load the pending buffer in `ms` of the clock and let the layer swap to it. */
function finishLoad(map, clock, layer, ms) {
  clock.ms += ms;
  map.loaded[layer.pending.sourceId] = true;
  map.fire('sourcedata', {sourceId: layer.pending.sourceId, tile: {}});
  map.fire('render');
}

test('after a swap the next step waits until loads are at most loadShare of the time', async () => {
  const {map, clock, layer} = await layerAt(11, 0.2);
  assert.equal(layer.shownZoom, 11);
  map.zoom = 11 + 1 / 32;
  map.fire('render');
  assert.equal(layer.pending.step, 11 * 32 + 1, 'the first step starts at once');
  finishLoad(map, clock, layer, 100);
  assert.equal(layer.shownZoom, 11 + 1 / 32);
  map.zoom = 11 + 2 / 32;
  const loadsBefore = map.setTilesCalls.length + Object.keys(map.sources).length;
  for (const ms of [1, 100, 200, 399]) {
    clock.ms = 100 + ms;
    map.fire('render');
    assert.equal(layer.pending, null, `no new load ${ms} ms after a 100 ms load (0.2 share: 400 ms pause)`);
  }
  assert.equal(map.setTilesCalls.length + Object.keys(map.sources).length, loadsBefore);
  assert.equal(layer.settled, false, 'not settled while the camera asks for another step');
  clock.ms = 100 + 400;
  map.fire('render');
  assert.equal(layer.pending.step, 11 * 32 + 2, 'the next step loads once the pause is over');
});

test('loadShare 1 loads the next step at once', async () => {
  const {map, clock, layer} = await layerAt(11, 1);
  map.zoom = 11 + 1 / 32;
  map.fire('render');
  finishLoad(map, clock, layer, 100);
  map.zoom = 11 + 2 / 32;
  map.fire('render');
  assert.equal(layer.pending.step, 11 * 32 + 2);
});

test('a camera that stops during the pause gets its step: the layer asks for a frame when the pause ends', async (t) => {
  t.mock.timers.enable({apis: ['setTimeout']});
  const {map, clock, layer} = await layerAt(11, 0.5);
  map.zoom = 11 + 1 / 32;
  map.fire('render');
  finishLoad(map, clock, layer, 50);
  map.zoom = 11 + 2 / 32; // the camera's last move: no render event after this one
  map.fire('render');
  assert.equal(layer.pending, null, 'paused (50 ms after a 50 ms load at share 0.5)');
  const repaints = map.repaints;
  t.mock.timers.tick(49);
  assert.equal(map.repaints, repaints, 'not before the pause ends');
  t.mock.timers.tick(1);
  assert.equal(map.repaints, repaints + 1, 'a frame is asked for when the pause ends');
  clock.ms += 50;
  map.fire('render');
  assert.equal(layer.pending.step, 11 * 32 + 2);
  layer.remove();
});

test('a loadShare outside (0, 1] is refused with its value', () => {
  for (const loadShare of [0, -0.5, 1.5, Number.NaN]) {
    assert.throws(
      () => new MorphLayer(morph, new StandInMap(11), {layers: [{id: 'l', type: 'line'}], loadShare}),
      /loadShare must be in \(0, 1\], got/,
    );
  }
});

