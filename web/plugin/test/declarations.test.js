// src/index.d.ts is written by hand: it must declare every value src/index.js exports, and nothing it doesn't.
import {readFileSync} from 'node:fs';
import {test} from 'node:test';
import assert from 'node:assert/strict';
import * as api from '../src/index.js';

test('the declarations name exactly the values the module exports', () => {
  const text = readFileSync(new URL('../src/index.d.ts', import.meta.url), 'utf8');
  const declared = [...text.matchAll(/^export (?:declare )?(?:class|function|const) (\w+)/gm)].map((m) => m[1]);
  assert.deepEqual([...new Set(declared)].sort(), Object.keys(api).sort());
});
