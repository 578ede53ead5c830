import assert from 'node:assert/strict';
import {test} from 'node:test';

import {
  COMPARE_LINE_WIDTH,
  comparisonLayers,
  contourLineLayers,
  contourSourceId,
  hillshadeOf,
  labelLayers,
  styleUrl,
} from '../js/stylerules.js';

const STYLE = {
  version: 8,
  glyphs: 'http://h/fonts/{fontstack}/{range}.pbf',
  sources: {
    'ccsm-contours': {type: 'vector', url: 'http://h/tiles/s/tilejson.json'},
    'ccsm-hillshade': {type: 'raster', tiles: ['http://h/hillshade/s/{z}/{x}/{y}.png'], tileSize: 256},
  },
  layers: [
    {id: 'background', type: 'background'},
    {id: 'hillshade', type: 'raster', source: 'ccsm-hillshade', paint: {'raster-opacity': 0.4}},
    {
      id: 'contours-rank-0',
      type: 'line',
      source: 'ccsm-contours',
      'source-layer': 'contours',
      filter: ['==', ['get', 'rank'], 0],
      paint: {'line-width': 0.7, 'line-opacity': ['interpolate', ['exponential', 2], ['zoom'], 11, 0, 12, 1]},
    },
    {id: 'contour-labels-rank-0', type: 'symbol', source: 'ccsm-contours', 'source-layer': 'contour_labels'},
  ],
};

test('styleUrl escapes the dataset id', () => {
  assert.equal(styleUrl('a b'), '/styles/a%20b/style.json');
});

test('hillshadeOf finds the raster layer and its source; null without one', () => {
  const h = hillshadeOf(STYLE);
  assert.equal(h.sourceId, 'ccsm-hillshade');
  assert.equal(h.layer.id, 'hillshade');
  assert.equal(h.source.tiles[0], 'http://h/hillshade/s/{z}/{x}/{y}.png');
  assert.equal(hillshadeOf({...STYLE, layers: STYLE.layers.filter((l) => l.type !== 'raster')}), null);
});

test('contour lines lose their source, keep filter and fade, and grow in with morph_fade', () => {
  const [line] = contourLineLayers(STYLE);
  assert.equal(line.source, undefined);
  assert.deepEqual(line.filter, ['==', ['get', 'rank'], 0]);
  assert.deepEqual(line.paint['line-opacity'], STYLE.layers[2].paint['line-opacity']);
  assert.deepEqual(line.paint['line-width'], ['*', 0.7, ['coalesce', ['get', 'morph_fade'], 1]]);
  assert.equal(contourSourceId(STYLE), 'ccsm-contours');
});

test('a zoom-ramped width keeps the ramp on top and grows in at every stop', () => {
  const ramp = ['interpolate', ['exponential', 2], ['zoom'], 10, ['case', ['==', ['get', 'level'], 1], 0.9, 0.7], 12, 1.5];
  const layers = [{...STYLE.layers[2], paint: {...STYLE.layers[2].paint, 'line-width': ramp}}];
  const [line] = contourLineLayers({...STYLE, layers});
  const grown = (w) => ['*', w, ['coalesce', ['get', 'morph_fade'], 1]];
  assert.deepEqual(line.paint['line-width'], [...ramp.slice(0, 4), grown(ramp[4]), 12, grown(1.5)]);
  const step = ['step', ['zoom'], 1, 10, 2];
  const [stepped] = contourLineLayers({...STYLE, layers: [{...layers[0], paint: {'line-width': step}}]});
  assert.deepEqual(stepped.paint['line-width'], ['step', ['zoom'], grown(1), 10, grown(2)]);
});

test('labels read from the given source', () => {
  const [label] = labelLayers(STYLE, 'page-labels');
  assert.equal(label.source, 'page-labels');
  assert.equal(label['source-layer'], 'contour_labels');
  assert.equal(labelLayers({layers: []}, 'x').length, 0);
});

test("the overlay's compared method keeps the style's filters and fades, in its own colour and thinner", () => {
  const lines = contourLineLayers(STYLE);
  const compared = comparisonLayers(lines, '#1b63c6');
  assert.equal(compared.length, lines.length);
  compared.forEach((c, i) => {
    assert.deepEqual(c.filter, lines[i].filter);
    assert.deepEqual(c.paint['line-opacity'], lines[i].paint['line-opacity']);
    assert.equal(c.paint['line-color'], '#1b63c6');
    assert.deepEqual(c.paint['line-width'], ['*', COMPARE_LINE_WIDTH, ['coalesce', ['get', 'morph_fade'], 1]]);
  });
  assert.notEqual(lines[0].paint['line-color'], '#1b63c6', 'the main layers are left as they were');
});
