import assert from 'node:assert/strict';
import {test} from 'node:test';

import {buildTileUrl, ccsmTemplate, parseCcsmUrl} from '../js/tileurl.js';

const PAGE = 'http://127.0.0.1:8000/?dataset=sample';

test('a ccsm template, filled in as MapLibre does, parses back to its key and tile', () => {
  const template = ccsmTemplate('s17');
  const url = template.replace('{z}', '12').replace('{x}', '803').replace('{y}', '1650');
  assert.deepEqual(parseCcsmUrl(url), {key: 's17', z: '12', x: '803', y: '1650'});
});

test('parseCcsmUrl refuses anything but ccsm://key/z/x/y, naming the URL', () => {
  for (const bad of ['ccsm://s1/12/803', 'ccsm://s1/12/803/x', 'http://s1/1/2/3', 'ccsm:///1/2/3', 'ccsm://s1/1/2/3/4']) {
    assert.throws(() => parseCcsmUrl(bad), {message: `bad ccsm tile URL ${bad}`});
  }
});

test('buildTileUrl fills the template and resolves it against the page', () => {
  const url = buildTileUrl('/tiles/sample/{z}/{x}/{y}.mvt', '12', '803', '1650', {zoom: 12.375}, PAGE);
  assert.equal(url, 'http://127.0.0.1:8000/tiles/sample/12/803/1650.mvt?zoom=12.375');
});

test("buildTileUrl keeps the template's own query and leaves out null and undefined", () => {
  const url = buildTileUrl(
    'https://tiles.example/t/{z}/{x}/{y}.mvt?v=3&key=abc',
    3,
    4,
    5,
    {zoom: 3.5, method: 'dp', t: null, extra: undefined},
    PAGE,
  );
  const parsed = new URL(url);
  assert.equal(parsed.origin + parsed.pathname, 'https://tiles.example/t/3/4/5.mvt');
  assert.deepEqual(Object.fromEntries(parsed.searchParams), {v: '3', key: 'abc', zoom: '3.5', method: 'dp'});
});

test('buildTileUrl sends t = 0 (a pinned t of zero is not "no t")', () => {
  const url = new URL(buildTileUrl('/t/{z}/{x}/{y}.mvt', 1, 0, 0, {t: 0}, PAGE));
  assert.equal(url.searchParams.get('t'), '0');
});

test('buildTileUrl overrides a parameter the template already sets', () => {
  const url = new URL(buildTileUrl('/t/{z}/{x}/{y}.mvt?method=ccsm', 1, 0, 0, {method: 'vw'}, PAGE));
  assert.deepEqual(url.searchParams.getAll('method'), ['vw']);
});
