// morph-worker.js's MorphRenderer (what the worker runs) and the page-side choice of renderer.
import {test} from 'node:test';
import assert from 'node:assert/strict';
import {readFileSync, readdirSync} from 'node:fs';
import {MorphRenderer, createRenderer} from '../src/morph-worker.js';
import {decodeMorphTile, renderMorphTile} from '../src/morphtile.js';
import {morphTileBytes, tProps} from './helpers.js';

const T = [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];
const BYTES = morphTileBytes([{id: 3, start: [[0, 0, 800, 0]], end: [[0, 800, 800, 800]], props: tProps(T, {elevation: 1})}]);
const OPTIONS = {scale: 2, fadeSpan: 0.125, keepSamples: false};

function manualQueue() {
  const jobs = [];
  return {jobs, schedule: (fn) => jobs.push(fn), runAll: () => { while (jobs.length) jobs.shift()(); }};
}

test('a step is drawn as renderMorphTile draws it, and the next steps in the zoom direction ahead', () => {
  const q = manualQueue();
  const r = new MorphRenderer({capacity: 4, ahead: 2, schedule: q.schedule});
  assert.deepEqual(r.add('11/5/6', BYTES.slice()), {empty: false});
  const request = {z: 11, step: 360, stepsPerZoom: 32, direction: -1, options: OPTIONS};
  const first = r.render('11/5/6', request);
  assert.deepEqual(first, renderMorphTile(decodeMorphTile(BYTES), 11, 360 / 32, OPTIONS));
  assert.equal(r.renders, 1);
  q.runAll();
  assert.equal(r.renders, 3); // steps 359 and 358 drawn ahead
  const ahead = r.render('11/5/6', {...request, step: 359});
  assert.deepEqual(ahead, renderMorphTile(decodeMorphTile(BYTES), 11, 359 / 32, OPTIONS));
  assert.equal(r.renders, 3, 'step 359 came from the drawn-ahead bytes');
});

test('tiles past the capacity are let go (render answers null), least recently used first', () => {
  const r = new MorphRenderer({capacity: 2});
  const request = {z: 11, step: 352, stepsPerZoom: 32, options: OPTIONS};
  r.add('a', BYTES.slice());
  r.add('b', BYTES.slice());
  assert.ok(r.render('a', request));
  r.add('c', BYTES.slice());
  assert.equal(r.render('b', request), null);
  assert.ok(r.render('a', request));
  assert.equal(r.get('b'), null);
  assert.deepEqual(r.add('e', new Uint8Array(0)), {empty: true});
});

test('without a Worker (node) the renderer runs in the page', async () => {
  assert.equal(typeof globalThis.Worker, 'undefined');
  assert.equal((await createRenderer({capacity: 2})).mode, 'local');
  assert.equal((await createRenderer({capacity: 2, useWorker: false})).mode, 'local');
});

test("the worker's module graph imports nothing by a bare name (a worker sees no import map)", () => {
  const seen = new Set();
  const visit = (name) => {
    if (seen.has(name)) return;
    seen.add(name);
    const text = readFileSync(new URL(`../src/${name}`, import.meta.url), 'utf8');
    for (const m of text.matchAll(/^(?:import|export)\b[^;'\n]*?\bfrom\s+'([^']+)'|^import\s+'([^']+)'/gm)) {
      const spec = m[1] ?? m[2];
      assert.ok(spec.startsWith('./'), `${name} imports '${spec}'`);
      visit(spec.slice(2));
    }
  };
  visit('morph-worker.js');
  assert.ok(seen.has('protobuf.js') && seen.has('morphtile.js') && seen.has('mvt.js'), [...seen].join());
  assert.ok(readdirSync(new URL('../src/', import.meta.url)).includes('morph-worker.js'));
});
