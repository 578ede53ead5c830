import {test} from 'node:test';
import assert from 'node:assert/strict';
import {gzipSync} from 'node:zlib';
import {CcsmMorph} from '../src/index.js';
import {tileUrl} from '../src/fetchers.js';
import {morphTileBytes, readTile, tProps} from './helpers.js';

const T = [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8];
const BYTES = morphTileBytes([{id: 3, start: [[0, 0, 800, 0]], end: [[0, 800, 800, 800]], props: tProps(T, {elevation: 1})}]);

function fakeFetch({gzip = false} = {}) {
  const urls = [];
  const fn = async (url) => {
    urls.push(url);
    if (url.endsWith('/0/0/0.mvt')) return new Response(null, {status: 204});
    return new Response(gzip ? gzipSync(BYTES) : BYTES, {status: 200});
  };
  return {fn, urls};
}

async function drawAt(morph, step, z = 11, x = 5, y = 6) {
  const {data} = await morph.loadTile({url: `${morph.protocol}://step${step}/${z}/${x}/${y}`});
  return readTile(new Uint8Array(data));
}

test('every step of a level is drawn from one fetch of the morph tile', async () => {
  const {fn, urls} = fakeFetch();
  const morph = new CcsmMorph({tiles: ['http://h/morph/s/{z}/{x}/{y}.mvt'], fetch: fn, stepsPerZoom: 32});
  const ys = [];
  for (let step = 11 * 32; step < 12 * 32; step++) {
    const tile = await drawAt(morph, step);
    ys.push(tile.contours.features[0].rings[0][0][1]);
  }
  assert.deepEqual(urls, ['http://h/morph/s/11/5/6.mvt']);
  assert.equal(morph.fetchCount, 1);
  // scale 2: start y 0, end y 1600 at extent 8192; t is linear here, so w = f.
  assert.equal(ys[0], 0);
  assert.equal(ys[16], 800);
  assert.equal(new Set(ys).size, 32);
});

test('gzipped tiles without Content-Encoding are unpacked; 204 is an empty tile', async () => {
  const {fn} = fakeFetch({gzip: true});
  const morph = new CcsmMorph({tiles: ['http://h/{z}/{x}/{y}.mvt'], fetch: fn});
  const tile = await drawAt(morph, 11 * 32 + 8);
  assert.equal(tile.contours.features[0].properties.t, 0.2);
  const {data} = await morph.loadTile({url: `${morph.protocol}://step0/0/0/0`});
  assert.equal(data.byteLength, 0);
});

test('a TileJSON url gives the tile template and the zoom range', async () => {
  const urls = [];
  const fn = async (url) => {
    urls.push(url);
    if (url.endsWith('tilejson.json')) {
      return Response.json({tiles: ['http://h/m/{z}/{x}/{y}.mvt'], minzoom: 3, maxzoom: 15, bounds: [1, 2, 3, 4]});
    }
    return new Response(BYTES);
  };
  const morph = new CcsmMorph({url: 'http://h/m/tilejson.json', fetch: fn});
  const meta = await morph.metadata();
  assert.equal(meta.minzoom, 3);
  assert.equal(meta.maxzoom, 15);
  await drawAt(morph, 11 * 32);
  assert.deepEqual(urls, ['http://h/m/tilejson.json', 'http://h/m/11/5/6.mvt']);
});

test('two instances do not share protocol names or tiles', () => {
  const a = new CcsmMorph({tiles: ['x/{z}/{x}/{y}']});
  const b = new CcsmMorph({tiles: ['x/{z}/{x}/{y}']});
  assert.notEqual(a.protocol, b.protocol);
  assert.match(a.tileUrl(352), /^ccsm-morph-[a-z0-9]+:\/\/step352\/\{z\}\/\{x\}\/\{y\}$/);
});

test('tile URL templates', () => {
  assert.equal(tileUrl('/m/{z}/{x}/{y}.mvt?v=1', 11, 5, 6, 'http://h/page'), 'http://h/m/11/5/6.mvt?v=1');
  assert.equal(tileUrl('/m/{z}/{x}/{-y}.mvt', 2, 1, 0), '/m/2/1/3.mvt');
});
