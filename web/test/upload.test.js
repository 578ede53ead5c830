import assert from 'node:assert/strict';
import {afterEach, test} from 'node:test';

import {ServiceError} from '../js/api.js';
import {progressFraction, uploadDataset} from '../js/upload.js';

const realFetch = globalThis.fetch;
afterEach(() => {
  globalThis.fetch = realFetch;
});

/** fetch answering each call with the next JSON body of `answers` (status 200 unless given). */
function fakeService(answers) {
  const calls = [];
  globalThis.fetch = async (url, options = {}) => {
    calls.push({url, options});
    const next = answers.shift();
    assert.ok(next, `unexpected request ${url}`);
    return new Response(JSON.stringify(next.body), {status: next.status ?? 200});
  };
  return calls;
}

const file = (name) => new File(['{"type":"FeatureCollection","features":[]}'], name);

test('progressFraction reads a fraction, a percentage or done/total counts', () => {
  assert.equal(progressFraction({build: 0.25}), 0.25);
  assert.equal(progressFraction({build: 1}), 1);
  assert.equal(progressFraction({progress: 40}), 0.4);
  assert.equal(progressFraction({build: {fraction: 0.7}}), 0.7);
  assert.equal(progressFraction({build: {done: 3, total: 12}}), 0.25);
  assert.equal(progressFraction({progress: {built: 1, count: 4}}), 0.25);
  assert.equal(progressFraction({build: {completed: 9, total: 10}}), 0.9);
});

test('progressFraction: unknown progress is null, a ready dataset is done', () => {
  assert.equal(progressFraction(null), null);
  assert.equal(progressFraction({state: 'building'}), null);
  assert.equal(progressFraction({build: {done: 0, total: 0}, state: 'building'}), null);
  assert.equal(progressFraction({build: {done: 2}, state: 'building'}), null);
  assert.equal(progressFraction({state: 'ready'}), 1);
});

test('uploadDataset posts the GeoJSON with its name and only the scales typed in', async () => {
  const calls = fakeService([{body: {id: 'hills', name: 'hills', state: 'ready'}}]);
  const seen = [];
  const upload = file('Hills 2.GeoJSON');
  const ds = await uploadDataset(upload, {
    scales: {source_scale: '25000', target_scale: ''},
    onProgress: (d, fraction) => seen.push([d.id, fraction]),
  });
  assert.equal(ds.id, 'hills');
  assert.deepEqual(seen, [['hills', 1]]);
  const url = new URL(calls[0].url, 'http://page/');
  assert.equal(url.pathname, '/datasets');
  assert.deepEqual(Object.fromEntries(url.searchParams), {name: 'Hills 2', source_scale: '25000'});
  assert.equal(calls[0].options.method, 'POST');
  assert.equal(calls[0].options.body, upload);
  assert.equal(calls[0].options.headers['Content-Type'], 'application/geo+json');
});

test('uploadDataset follows the build until it is ready', async () => {
  const calls = fakeService([
    {body: {id: 'a b', state: 'building', build: {done: 1, total: 4}}},
    {body: {id: 'a b', state: 'ready'}},
  ]);
  const seen = [];
  const ds = await uploadDataset(file('a b.json'), {onProgress: (d, f) => seen.push(f)});
  assert.equal(ds.state, 'ready');
  assert.deepEqual(seen, [0.25, 1]);
  assert.equal(calls[1].url, '/datasets/a%20b');
});

test('uploadDataset: a failed build rejects with the reason', async () => {
  fakeService([{body: {id: 'x', name: 'ridge', state: 'failed', build: {error: 'no LineString features'}}}]);
  await assert.rejects(uploadDataset(file('ridge.geojson')), (err) => {
    assert.ok(err instanceof ServiceError);
    assert.equal(err.message, 'Building “ridge” failed: no LineString features');
    return true;
  });
  fakeService([{body: {id: 'x', state: 'failed'}}]);
  await assert.rejects(uploadDataset(file('ridge.geojson')), {
    message: 'Building “ridge.geojson” failed: no reason given',
  });
});

test('uploadDataset: an answer without an id is an error, not a poll of /datasets/undefined', async () => {
  const calls = fakeService([{body: {state: 'building'}}]);
  await assert.rejects(uploadDataset(file('c.geojson')), {
    message: 'Upload of “c.geojson”: the service answered without a dataset id',
  });
  assert.equal(calls.length, 1);
});

test("uploadDataset: the service's 400 message reaches the caller", async () => {
  fakeService([{status: 400, body: {detail: 'the file is not GeoJSON'}}]);
  await assert.rejects(uploadDataset(file('d.geojson')), {
    message: 'Upload of “d.geojson” failed (HTTP 400): the file is not GeoJSON',
  });
});
