import {test} from 'node:test';
import assert from 'node:assert/strict';
import {encodeGeometry, encodeMvt} from '../src/mvt.js';
import {readTile} from './helpers.js';

test('encode then decode with @mapbox/vector-tile gives the layers, ids, geometry and properties back', () => {
  const bytes = encodeMvt([
    {
      name: 'contours',
      extent: 4096,
      features: [
        {
          id: 17,
          type: 2,
          parts: [[0, 0, 100, 50, 4200, -64], [10, 10, 20, 30]],
          properties: {elevation: 340, index: true, t: 0.4321, name: 'a', depth: -5, missing: null},
        },
        {id: 18, type: 2, parts: [[5, 5, 6, 7]], properties: {elevation: 340.5, index: false, t: 0.4321}},
      ],
    },
    {name: 'points', extent: 512, features: [{id: 1, type: 1, parts: [[1, 2, 3, 4]], properties: {}}]},
  ]);
  const tile = readTile(bytes);
  assert.deepEqual(Object.keys(tile).sort(), ['contours', 'points']);
  const [a, b] = tile.contours.features;
  assert.equal(tile.contours.extent, 4096);
  assert.equal(a.id, 17);
  assert.equal(a.type, 2);
  assert.deepEqual(a.rings, [[[0, 0], [100, 50], [4200, -64]], [[10, 10], [20, 30]]]);
  assert.deepEqual(a.properties, {elevation: 340, index: true, t: 0.4321, name: 'a', depth: -5});
  assert.deepEqual(b.properties, {elevation: 340.5, index: false, t: 0.4321});
  assert.deepEqual(b.rings, [[[5, 5], [6, 7]]]);
  assert.equal(tile.points.extent, 512);
  assert.equal(tile.points.features[0].type, 1);
  assert.deepEqual(tile.points.features[0].rings, [[[1, 2]], [[3, 4]]]);
});

test('coordinates are rounded, repeated points dropped, degenerate parts and features left out', () => {
  const tile = readTile(
    encodeMvt([
      {
        name: 'l',
        features: [
          {id: 1, type: 2, parts: [[0.4, 0.4, 0.2, -0.3, 9.6, 9.5], [3, 3, 3.2, 2.9]]},
          {id: 2, type: 2, parts: [[1, 1, 1.1, 1.2]]},
        ],
      },
    ]),
  );
  assert.equal(tile.l.features.length, 1);
  assert.deepEqual(tile.l.features[0].rings, [[[0, 0], [10, 10]]]);
});

test('polygons are closed with ClosePath', () => {
  const g = encodeGeometry(3, [[0, 0, 10, 0, 10, 10, 0, 0]]);
  assert.equal(g[g.length - 1], 15); // ClosePath, count 1
  const tile = readTile(encodeMvt([{name: 'p', features: [{type: 3, parts: [[0, 0, 10, 0, 10, 10]]}]}]));
  assert.deepEqual(tile.p.features[0].rings[0], [[0, 0], [10, 0], [10, 10], [0, 0]]);
});

test('equal values are stored once in the value table', () => {
  const features = Array.from({length: 50}, (_, i) => ({id: i, type: 2, parts: [[0, 0, i + 1, 1]], properties: {elevation: 100, index: i % 2 === 0}}));
  const small = encodeMvt([{name: 'l', features}]).length;
  const distinct = encodeMvt([{name: 'l', features: features.map((f, i) => ({...f, properties: {elevation: 100 + i + 0.5, index: true}}))}]).length;
  assert.ok(small < distinct, `${small} >= ${distinct}`);
});
