import {test} from 'node:test';
import assert from 'node:assert/strict';
import {fadeAt, levelFraction, morphWeight, stepIndex, tAt, tSamples} from '../src/tinterp.js';

// Not linear in f on purpose: t follows a table that is piecewise linear in log scale.
const T = [0.2, 0.23, 0.27, 0.3, 0.36, 0.41, 0.45, 0.52, 0.6];

test('t at the sample points equals the samples', () => {
  for (let k = 0; k <= 8; k++) assert.equal(tAt(T, k / 8), T[k]);
});

test('t between two samples is on the straight line between them', () => {
  for (let k = 0; k < 8; k++) {
    for (const u of [0.25, 0.5, 0.9]) {
      const expected = T[k] + u * (T[k + 1] - T[k]);
      assert.ok(Math.abs(tAt(T, (k + u) / 8) - expected) < 1e-12, `k=${k} u=${u}`);
    }
  }
});

test('t is clamped outside the level and constant with one sample', () => {
  assert.equal(tAt(T, -0.5), T[0]);
  assert.equal(tAt(T, 1.5), T[8]);
  assert.equal(tAt([0.4], 0.7), 0.4);
});

test('the weight runs from 0 at the start to 1 at the end, and follows t, not f', () => {
  assert.equal(morphWeight(T, 0), 0);
  assert.equal(morphWeight(T, 1), 1);
  const w = morphWeight(T, 3 / 8);
  assert.ok(Math.abs(w - (0.3 - 0.2) / (0.6 - 0.2)) < 1e-12);
  assert.notEqual(w, 3 / 8);
});

test('a contour that does not change over the level does not move', () => {
  assert.equal(morphWeight([0.5, 0.5, 0.5], 0.7), 0);
});

test('t samples are read from the properties in order, and need t', () => {
  assert.deepEqual(tSamples({t: 0.1, t1: 0.2, t2: 0.3, t4: 0.9}), [0.1, 0.2, 0.3]);
  assert.equal(tSamples({elevation: 300}), null);
});

test('a contour with min_zoom is hidden up to it, then fades in over the span', () => {
  assert.equal(fadeAt(null, 11.2, 0.125), 1);
  assert.equal(fadeAt(11.5, 11.5, 0.125), 0);
  assert.equal(fadeAt(11.5, 11.4, 0.125), 0);
  assert.ok(Math.abs(fadeAt(11.5, 11.5625, 0.125) - 0.5) < 1e-12);
  assert.equal(fadeAt(11.5, 11.7, 0.125), 1);
  assert.equal(fadeAt(11.5, 11.51, 0), 1);
});

test('steps and level fractions', () => {
  assert.equal(stepIndex(11.5, 32), 368);
  assert.equal(stepIndex(11.999999999, 32), 384); // float noise just below a step
  assert.equal(stepIndex(11.03, 32), 352);
  assert.equal(levelFraction(11.25, 11), 0.25);
  assert.equal(levelFraction(12.25, 11), 1);
  assert.equal(levelFraction(11.25, 12), 0);
});
