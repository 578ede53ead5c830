// MorphLayer's pacing of step loads (layer.js): a step starts loading only while the loads of the last 3 s
// took at most `loadShare` of it, and a camera that stops during the pause still gets its step. A map stand-in
// records what the layer asks of MapLibre; the clock is the test's.
import assert from 'node:assert/strict';
import {test} from 'node:test';
import {LOAD_WINDOW_MS, MorphLayer} from '../src/layer.js';

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

/** Ask for the next step (the camera moved on by one) and report whether its load started. */
function nextStepStarts(map, layer) {
  map.zoom += 1 / 32;
  map.fire('render');
  return layer.pending !== null;
}

test('steps load back to back until the loads of the last 3 s took loadShare of it, then wait', async () => {
  const {map, clock, layer} = await layerAt(11, 0.2); // 600 ms of loads per 3,000 ms window
  assert.equal(LOAD_WINDOW_MS, 3000);
  assert.equal(layer.shownZoom, 11);
  for (let k = 1; k <= 3; k++) {
    assert.ok(nextStepStarts(map, layer), `step ${k} starts at once (${(k - 1) * 250} ms of loads so far)`);
    finishLoad(map, clock, layer, 250);
    assert.equal(layer.shownZoom, 11 + k / 32);
  }
  // 750 ms of loads in the window: the next waits until the window holds 600, when [0, 150] has left it.
  map.zoom += 1 / 32;
  for (const t of [750, 1500, 3000, 3140]) {
    clock.ms = t;
    map.fire('render');
    assert.equal(layer.pending, null, `no new load at ${t} ms`);
  }
  assert.equal(layer.settled, false, 'not settled while the camera asks for another step');
  clock.ms = 3152;
  map.fire('render');
  assert.equal(layer.pending.step, 11 * 32 + 4, 'the next step loads once the window allows it');
});

test('loadShare 1 never waits', async () => {
  const {map, clock, layer} = await layerAt(11, 1);
  for (let k = 1; k <= 6; k++) {
    assert.ok(nextStepStarts(map, layer), `step ${k}`);
    finishLoad(map, clock, layer, 1000);
  }
});

test('a camera that stops during the pause gets its step: the layer asks for a frame when the pause ends', async (t) => {
  t.mock.timers.enable({apis: ['setTimeout']});
  const {map, clock, layer} = await layerAt(11, 0.5); // 1,500 ms of loads per window
  assert.ok(nextStepStarts(map, layer));
  finishLoad(map, clock, layer, 2000);
  assert.ok(!nextStepStarts(map, layer), 'paused: 2,000 ms of loads in the window'); // the camera's last move
  const repaints = map.repaints;
  t.mock.timers.tick(1490);
  assert.equal(map.repaints, repaints, 'not before the pause ends (1,500 ms: [0, 500] out of the window)');
  t.mock.timers.tick(12);
  assert.equal(map.repaints, repaints + 1, 'a frame is asked for when the pause ends');
  clock.ms += 1502;
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

