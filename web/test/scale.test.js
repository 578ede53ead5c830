import assert from 'node:assert/strict';
import {test} from 'node:test';

import {
  clampMorphZoom,
  formatScale,
  morphZoomForTile,
  quantiseZoom,
  scaleDenominator,
  SCALE_AT_ZOOM_0,
} from '../js/scale.js';

// DESIGN.md section 4, written out here on its own: 512 px tiles, the OGC pixel of 0.28 mm.
const EARTH_RADIUS_M = 6378137;
const scaleFromFormula = (zoom, latDeg) =>
  (2 * Math.PI * EARTH_RADIUS_M * Math.cos((latDeg * Math.PI) / 180)) / (512 * 2 ** zoom) / 0.00028;
const zoomFromFormula = (scale, latDeg) =>
  Math.log2((2 * Math.PI * EARTH_RADIUS_M * Math.cos((latDeg * Math.PI) / 180)) / (512 * scale * 0.00028));

const close = (actual, expected, rel = 1e-12) =>
  assert.ok(Math.abs(actual - expected) <= rel * Math.abs(expected), `${actual} is not ${expected}`);

test('the scale at zoom 0 on the equator is 1:279,541,132', () => {
  assert.equal(Math.floor(SCALE_AT_ZOOM_0), 279541132);
  close(scaleDenominator(0, 0), scaleFromFormula(0, 0));
});

test('scaleDenominator follows the formula over zooms and latitudes', () => {
  for (const zoom of [0, 3.5, 10, 11.125, 17.875, 22]) {
    for (const lat of [0, 32.9, -45, 60, 84.9]) close(scaleDenominator(zoom, lat), scaleFromFormula(zoom, lat));
  }
});

test('zoom -> scale -> zoom round trip: the zoom for 1:S gives back 1:S', () => {
  for (const scale of [5000, 25000, 50000, 250000, 1e6, 5e7]) {
    for (const lat of [0, 33, -51.5, 70]) close(scaleDenominator(zoomFromFormula(scale, lat), lat), scale, 1e-9);
  }
});

test('one zoom level more halves the scale denominator', () => {
  close(scaleDenominator(12.3, 40) / scaleDenominator(13.3, 40), 2);
});

test('formatScale keeps three significant digits, grouped', () => {
  assert.equal(formatScale(123456), '1:123,000');
  assert.equal(formatScale(1234567), '1:1,230,000');
  assert.equal(formatScale(279541132), '1:280,000,000');
  assert.equal(formatScale(50000), '1:50,000');
  assert.equal(formatScale(99960), '1:100,000');
  assert.equal(formatScale(432), '1:432');
  assert.equal(formatScale(47.4), '1:47');
});

test('formatScale shows a dash for no usable scale', () => {
  for (const bad of [0, -5, NaN, Infinity, undefined]) assert.equal(formatScale(bad), '1:–');
});

test('quantiseZoom rounds down to eighths', () => {
  assert.equal(quantiseZoom(10), 10);
  assert.equal(quantiseZoom(10.1249), 10);
  assert.equal(quantiseZoom(10.125), 10.125);
  assert.equal(quantiseZoom(10.99), 10.875);
  assert.equal(quantiseZoom(3.7, 4), 3.5);
});

test('quantiseZoom is not thrown one step down by float noise', () => {
  // A zoom from a log2 of scales lands a hair below the grid: log2(3 * 2^14.5) - log2(3) = 14.499999999999998.
  assert.equal(quantiseZoom(Math.log2(3 * 2 ** 14.5) - Math.log2(3)), 14.5);
  assert.equal(quantiseZoom(11.375 - 1e-12), 11.375);
});

test('morphZoomForTile keeps the morph zoom inside [z, z + 1) of the tile', () => {
  assert.equal(morphZoomForTile(10.5, 10), 10.5);
  assert.equal(morphZoomForTile(10, 10), 10);
  // Asked in passing for a tile of the next z: its lowest zoom.
  assert.equal(morphZoomForTile(10.875, 11), 11);
  // Over-zoomed past maxzoom 12: the last step of z = 12.
  assert.equal(morphZoomForTile(14.25, 12), 12.875);
  assert.equal(morphZoomForTile(14.25, 12, 4), 12.75);
});

test('clampMorphZoom keeps a source inside [minzoom, maxzoom + 1)', () => {
  assert.equal(clampMorphZoom(11.25, 8, 14), 11.25);
  assert.equal(clampMorphZoom(3.5, 8, 14), 8);
  assert.equal(clampMorphZoom(14.875, 8, 14), 14.875);
  assert.equal(clampMorphZoom(16.5, 8, 14), 14.875);
  assert.equal(clampMorphZoom(16.5, 0, 14, 2), 14.5);
});
