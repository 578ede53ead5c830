import {test} from 'node:test';
import assert from 'node:assert/strict';
import {decodeMorphTile, interpolateFeatures, renderMorphTile} from '../src/morphtile.js';
import {morphWeight} from '../src/tinterp.js';
import {morphTileBytes, readTile, tProps} from './helpers.js';

const T = [0.2, 0.23, 0.27, 0.3, 0.36, 0.41, 0.45, 0.52, 0.6];
const CONTOURS = [
  {
    id: 7,
    start: [[0, 0, 100, 0, 200, 40], [300, 300, 310, 320]],
    end: [[0, 10, 120, 30, 180, 80], [300, 400, 330, 300]],
    props: tProps(T, {elevation: 320, index: true}),
  },
  {
    id: 9,
    start: [[1000, 1000, 1100, 1200]],
    end: [[1000, 1000, 1100, 1200]],
    props: tProps([0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5], {elevation: 340, index: false}),
  },
  {
    id: 11,
    start: [[2000, 0, 2100, 50]],
    end: [[2040, 0, 2100, 90]],
    props: tProps(T, {elevation: 360, index: false, min_zoom: 11.5}),
  },
];

const tile = decodeMorphTile(morphTileBytes(CONTOURS));
const flat = (parts) => parts.map((p) => Array.from(p));

test('decoding keeps ids, properties, t samples, min_zoom and matches every feature to its end', () => {
  assert.equal(tile.extent, 4096);
  assert.equal(tile.mismatched, 0);
  assert.deepEqual(tile.features.map((f) => f.id), [7, 9, 11]);
  assert.deepEqual(tile.features[0].samples, T);
  assert.equal(tile.features[2].minZoom, 11.5);
  assert.equal(tile.features[0].properties.elevation, 320);
});

test('at f = 0 the drawn layer is the start layer', () => {
  const out = interpolateFeatures(tile, 11, 11);
  assert.deepEqual(flat(out[0].parts), CONTOURS[0].start);
  assert.deepEqual(flat(out[1].parts), CONTOURS[1].start);
  assert.equal(out[0].properties.t, T[0]);
});

test('as f -> 1 the drawn layer goes to the end layer', () => {
  const near = interpolateFeatures(tile, 11, 11.999999);
  CONTOURS[0].end.forEach((part, j) =>
    part.forEach((v, i) => assert.ok(Math.abs(near[0].parts[j][i] - v) < 1e-3, `part ${j} value ${i}`)),
  );
  const atEnd = interpolateFeatures(tile, 11, 12);
  assert.deepEqual(flat(atEnd[0].parts), CONTOURS[0].end);
  assert.deepEqual(flat(atEnd[2].parts), CONTOURS[2].end);
  assert.equal(atEnd[0].properties.t, T[8]);
});

test('inside the level every point moves by the weight from t, on its straight path', () => {
  const f = 0.3;
  const w = morphWeight(T, f);
  const out = interpolateFeatures(tile, 11, 11 + f);
  CONTOURS[0].start.forEach((part, j) =>
    part.forEach((v, i) => {
      const expected = v + w * (CONTOURS[0].end[j][i] - v);
      assert.ok(Math.abs(out[0].parts[j][i] - expected) < 1e-9);
    }),
  );
  // t at 11.3 lies between the samples at 11.25 and 11.375.
  assert.ok(out[0].properties.t > T[2] && out[0].properties.t < T[3]);
});

test('a contour is left out up to its min_zoom and fades in after it', () => {
  const ids = (zoom) => interpolateFeatures(tile, 11, zoom, {fadeSpan: 0.125}).map((f) => f.id);
  assert.deepEqual(ids(11.5), [7, 9]);
  assert.deepEqual(ids(11.53), [7, 9, 11]);
  const fade = (zoom) => interpolateFeatures(tile, 11, zoom, {fadeSpan: 0.125}).find((f) => f.id === 11).properties.morph_fade;
  assert.ok(Math.abs(fade(11.5625) - 0.5) < 1e-9);
  assert.equal(fade(11.8), 1);
  assert.equal(interpolateFeatures(tile, 11, 11.2)[0].properties.morph_fade, 1);
});

test('t1 ... t8 are dropped from the drawn tile unless kept', () => {
  const [f] = interpolateFeatures(tile, 11, 11.5);
  assert.deepEqual(Object.keys(f.properties).sort(), ['elevation', 'index', 'morph_fade', 't']);
  const [g] = interpolateFeatures(tile, 11, 11.5, {keepSamples: true});
  assert.equal(g.properties.t8, T[8]);
});

test('a feature whose end has another shape does not move (and is counted)', () => {
  const odd = decodeMorphTile(
    morphTileBytes([{id: 1, start: [[0, 0, 10, 10, 20, 0]], end: [[0, 5, 10, 15]], props: tProps(T)}]),
  );
  assert.equal(odd.mismatched, 1);
  assert.deepEqual(flat(interpolateFeatures(odd, 11, 11.9)[0].parts), [[0, 0, 10, 10, 20, 0]]);
});

test('the rendered tile decodes to the interpolated layer, at the output scale', () => {
  const zoom = 11.40625;
  const decoded = readTile(renderMorphTile(tile, 11, zoom, {scale: 2}));
  assert.deepEqual(Object.keys(decoded), ['contours']);
  assert.equal(decoded.contours.extent, 8192);
  const expected = interpolateFeatures(tile, 11, zoom, {scale: 2});
  assert.equal(decoded.contours.features.length, expected.length);
  decoded.contours.features.forEach((f, k) => {
    assert.equal(f.id, expected[k].id);
    assert.deepEqual(f.properties, expected[k].properties);
    f.rings.forEach((ring, j) =>
      ring.forEach(([x, y], i) => {
        assert.ok(Math.abs(x - expected[k].parts[j][2 * i]) <= 0.5);
        assert.ok(Math.abs(y - expected[k].parts[j][2 * i + 1]) <= 0.5);
      }),
    );
  });
});

test('an empty tile decodes to no features', () => {
  assert.deepEqual(decodeMorphTile(new Uint8Array(0)).features, []);
});
