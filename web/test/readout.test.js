import assert from 'node:assert/strict';
import {test} from 'node:test';

import {fmtT, tooltipText, tReadout, zoomReadout} from '../js/readout.js';

test('fmtT shows three decimals of numbers and numeric strings', () => {
  assert.equal(fmtT(0.25), '0.250');
  assert.equal(fmtT('0.12345'), '0.123');
  assert.equal(fmtT(1), '1.000');
});

test('zoomReadout adds the morph zoom only once one is on screen', () => {
  assert.equal(zoomReadout(10.5312, null), 'zoom 10.53');
  assert.equal(zoomReadout(10.5312, undefined), 'zoom 10.53');
  assert.equal(zoomReadout(10.5312, 10.5), 'zoom 10.53 · morph 10.500');
  assert.equal(zoomReadout(3, 0), 'zoom 3.00 · morph 0.000');
});

test('tReadout: a pinned t wins, even a pinned 0 and even for the original', () => {
  assert.equal(tReadout(0.4, 'ccsm', {min: 0, max: 1, median: 0.5}), 't = 0.400 (pinned)');
  assert.equal(tReadout(0, 'original', null), 't = 0.000 (pinned)');
});

test('tReadout: the original method has t = 0', () => {
  assert.equal(tReadout(null, 'original', {min: 0.2, max: 0.3, median: 0.25}), 't = 0 (original)');
});

test('tReadout: the median of the t on screen, with the range only when it is wider than 0.0005', () => {
  assert.equal(tReadout(null, 'ccsm', null), 't –');
  assert.equal(tReadout(null, 'dp', {min: 0.3, max: 0.3004, median: 0.3002}), 't ≈ 0.300');
  assert.equal(tReadout(null, 'dp', {min: 0.1, max: 0.4, median: 0.25}), 't ≈ 0.250 (0.100–0.400)');
});

test('tooltipText: elevation, index flag, t and method', () => {
  assert.equal(tooltipText({elevation: 120, index: 1, t: 0.25}, 'CCSM'), '120 m (index) · t = 0.250 · CCSM');
  assert.equal(tooltipText({elevation: 97.25, index: 0, t: '0.5'}, 'Douglas–Peucker'), '97.3 m · t = 0.500 · Douglas–Peucker');
  assert.equal(tooltipText({elevation: '250'}, ''), '250 m · t – · ');
});

test('tooltipText: missing or non-numeric values show as unknown', () => {
  assert.equal(tooltipText(null, 'CCSM'), '? m · t – · CCSM');
  assert.equal(tooltipText({elevation: 'high', t: 'n/a'}, 'CCSM'), '? m · t – · CCSM');
});
