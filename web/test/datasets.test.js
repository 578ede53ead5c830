import assert from 'node:assert/strict';
import {test} from 'node:test';

import {datasetLabel, initialDataset, tilejsonUrl} from '../js/datasets.js';

test('tilejsonUrl takes the link the service gives, in this order', () => {
  const links = {tilejson: '/a.json', tilejson_url: '/b.json', links: {tilejson: '/c.json'}, id: 'x'};
  assert.equal(tilejsonUrl(links), '/a.json');
  assert.equal(tilejsonUrl({...links, tilejson: undefined}), '/b.json');
  assert.equal(tilejsonUrl({links: {tilejson: '/c.json'}, id: 'x'}), '/c.json');
});

test('tilejsonUrl falls back to the documented route, with the id escaped', () => {
  assert.equal(tilejsonUrl({id: 'sample'}), '/tiles/sample/tilejson.json');
  assert.equal(tilejsonUrl({id: 'my hills/2'}), '/tiles/my%20hills%2F2/tilejson.json');
});

test('datasetLabel: the name (else the id) and the build state', () => {
  assert.equal(datasetLabel({id: 'a', name: 'Alps', state: 'ready'}), 'Alps');
  assert.equal(datasetLabel({id: 'a', state: 'ready'}), 'a');
  assert.equal(datasetLabel({id: 'a', name: 'Alps', state: 'building'}), 'Alps (building…)');
  assert.equal(datasetLabel({id: 'a', name: 'Alps', state: 'failed'}), 'Alps (failed)');
});

test('initialDataset: the one asked for when it is ready, else the first ready one', () => {
  const list = [
    {id: 'a', state: 'building'},
    {id: 'b', state: 'ready'},
    {id: 'c', state: 'ready'},
    {id: 'd', state: 'failed'},
  ];
  assert.equal(initialDataset(list, 'c').id, 'c');
  assert.equal(initialDataset(list, null).id, 'b');
  assert.equal(initialDataset(list, 'a').id, 'b');
  assert.equal(initialDataset(list, 'd').id, 'b');
  assert.equal(initialDataset(list, 'nope').id, 'b');
  assert.equal(initialDataset([{id: 'a', state: 'building'}], 'a'), undefined);
  assert.equal(initialDataset([], 'a'), undefined);
});
