import {test} from 'node:test';
import assert from 'node:assert/strict';
import {PromiseCache} from '../src/cache.js';

test('each key is loaded once, and concurrent callers share the load', async () => {
  const calls = [];
  const cache = new PromiseCache(10, async (key) => {
    calls.push(key);
    return key.toUpperCase();
  });
  const [a, b] = await Promise.all([cache.get('a'), cache.get('a')]);
  assert.equal(a, 'A');
  assert.equal(b, 'A');
  assert.equal(await cache.get('a'), 'A');
  assert.deepEqual(calls, ['a']);
});

test('a failed load is forgotten and tried again', async () => {
  let n = 0;
  const cache = new PromiseCache(10, async () => {
    n += 1;
    if (n === 1) throw new Error('boom');
    return n;
  });
  await assert.rejects(cache.get('k'), /boom/);
  assert.equal(await cache.get('k'), 2);
});

test('the least recently used entry goes first', async () => {
  const calls = [];
  const cache = new PromiseCache(2, async (key) => calls.push(key));
  await cache.get('a');
  await cache.get('b');
  await cache.get('a'); // a is now newer than b
  await cache.get('c'); // evicts b
  assert.ok(cache.has('a') && cache.has('c') && !cache.has('b'));
  await cache.get('b');
  assert.deepEqual(calls, ['a', 'b', 'c', 'b']);
});
