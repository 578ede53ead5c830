import assert from 'node:assert/strict';
import {afterEach, test} from 'node:test';

import {formatDetail, getJSON, request, ServiceError} from '../js/api.js';

const realFetch = globalThis.fetch;
afterEach(() => {
  globalThis.fetch = realFetch;
});

/** Replace fetch by one that records its calls and answers with respond(url, options). */
function fakeFetch(respond) {
  const calls = [];
  globalThis.fetch = async (url, options) => {
    calls.push({url, options});
    return respond(url, options);
  };
  return calls;
}

test('formatDetail: nothing, a string, an object', () => {
  assert.equal(formatDetail(null), '');
  assert.equal(formatDetail(undefined), '');
  assert.equal(formatDetail('dataset not found'), 'dataset not found');
  assert.equal(formatDetail({message: 'boom'}), 'boom');
  assert.equal(formatDetail({msg: 'bad'}), 'bad');
  assert.equal(formatDetail({code: 7}), '{"code":7}');
  assert.equal(formatDetail(42), '42');
});

test('formatDetail: a FastAPI 422 list names each field, without the "body" prefix', () => {
  const detail = [
    {loc: ['query', 'zoom'], msg: 'Input should be less than 13', type: 'less_than'},
    {loc: ['body', 'source_scale'], msg: 'must be below target_scale'},
    {loc: ['body'], msg: 'not GeoJSON'},
    {msg: 'no location'},
    'plain text',
  ];
  assert.equal(
    formatDetail(detail),
    'query.zoom: Input should be less than 13; source_scale: must be below target_scale; not GeoJSON; ' +
      'no location; plain text',
  );
});

test('request returns the response of a 2xx answer', async () => {
  fakeFetch(() => new Response('{}', {status: 200}));
  const response = await request('/datasets');
  assert.equal(response.status, 200);
});

test('request: a 422 says what failed, the status and the fields', async () => {
  const body = {detail: [{loc: ['query', 'source_scale'], msg: 'must be positive'}]};
  fakeFetch(() => new Response(JSON.stringify(body), {status: 422, statusText: 'Unprocessable Entity'}));
  await assert.rejects(request('/datasets?x', {method: 'POST'}, 'Upload of “a.geojson”'), (err) => {
    assert.ok(err instanceof ServiceError);
    assert.equal(err.message, 'Upload of “a.geojson” failed (HTTP 422): query.source_scale: must be positive');
    assert.equal(err.status, 422);
    assert.deepEqual(err.body, body);
    return true;
  });
});

test('request: a non-JSON error body is shown, cut to 200 characters', async () => {
  fakeFetch(() => new Response('x'.repeat(500), {status: 502, statusText: 'Bad Gateway'}));
  await assert.rejects(request('/tiles/a'), {message: `GET /tiles/a failed (HTTP 502): ${'x'.repeat(200)}`});
});

test('request: an empty error body falls back to the status text, then to "no details"', async () => {
  fakeFetch(() => new Response('', {status: 404, statusText: 'Not Found'}));
  await assert.rejects(request('/datasets/zz', {}, 'Dataset “zz”'), {message: 'Dataset “zz” failed (HTTP 404): Not Found'});
  fakeFetch(() => new Response(null, {status: 500}));
  await assert.rejects(request('/x'), {message: 'GET /x failed (HTTP 500): no details'});
});

test('request: a network failure says the service is unreachable', async () => {
  fakeFetch(() => {
    throw new TypeError('fetch failed');
  });
  await assert.rejects(request('/datasets', {method: 'DELETE'}), (err) => {
    assert.ok(err instanceof ServiceError);
    assert.equal(err.message, 'DELETE /datasets failed: the tile service is unreachable (fetch failed)');
    assert.equal(err.status, 0);
    return true;
  });
});

test('request: an abort is passed on as it is, not turned into a service error', async () => {
  const abort = new DOMException('The operation was aborted.', 'AbortError');
  fakeFetch(() => {
    throw abort;
  });
  await assert.rejects(request('/tiles/a'), (err) => err === abort);
});

test('getJSON asks for JSON and returns the parsed body', async () => {
  const calls = fakeFetch(() => new Response('[{"id":"a"}]', {status: 200}));
  assert.deepEqual(await getJSON('/datasets', 'Listing datasets'), [{id: 'a'}]);
  assert.equal(calls[0].options.headers.Accept, 'application/json');
});
