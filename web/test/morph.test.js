import assert from 'node:assert/strict';
import {test} from 'node:test';

import {tStats} from '../js/morph.js';

const feature = (t) => ({properties: {t}});

test('tStats: min, max, median and count of t', () => {
  assert.deepEqual(tStats([0.5, 0.1, 0.3].map(feature)), {min: 0.1, max: 0.5, median: 0.3, count: 3});
  // Numeric strings count too (t goes through Number()).
  assert.deepEqual(tStats(['0.2', '0.4', '0.9'].map(feature)), {min: 0.2, max: 0.9, median: 0.4, count: 3});
});

test('tStats sorts numerically, not as text', () => {
  assert.deepEqual(tStats([10, 9, 100].map(feature)), {min: 9, max: 100, median: 10, count: 3});
});

test('tStats skips features without a numeric t', () => {
  const features = [feature(0.7), {properties: {}}, {}, feature('n/a'), feature(0.2), feature(0.4)];
  assert.deepEqual(tStats(features), {min: 0.2, max: 0.7, median: 0.4, count: 3});
});

test('tStats is null when no feature has a t', () => {
  assert.equal(tStats([]), null);
  assert.equal(tStats([{properties: {}}, feature('x')]), null);
});
