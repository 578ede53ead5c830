// The plugin as a package: `npm pack` ships exactly src/ (the modules and their declarations), and a fresh
// project that installs the tarball imports it from node and type-checks against its declarations.
// Needs npm (and, for the peer dependency, maplibre-gl in npm's cache or the registry): fails without them.
import {execFileSync} from 'node:child_process';
import {mkdirSync, mkdtempSync, readdirSync, readFileSync, rmSync, writeFileSync} from 'node:fs';
import {tmpdir} from 'node:os';
import {join} from 'node:path';
import {after, before, test} from 'node:test';
import assert from 'node:assert/strict';

const PLUGIN = new URL('..', import.meta.url).pathname;
const manifest = JSON.parse(readFileSync(join(PLUGIN, 'package.json'), 'utf8'));
const TSC = join(PLUGIN, 'node_modules', '.bin', 'tsc');

let work;
let packed;
let project;

function run(command, args, cwd) {
  return execFileSync(command, args, {cwd, encoding: 'utf8', timeout: 180_000, stdio: ['ignore', 'pipe', 'pipe']});
}

before(() => {
  work = mkdtempSync(join(tmpdir(), 'ccsm-morph-pack-'));
  [packed] = JSON.parse(run('npm', ['pack', '--json', '--pack-destination', work, '--loglevel=error'], PLUGIN));
  project = join(work, 'fresh');
  mkdirSync(project);
  writeFileSync(join(project, 'package.json'), JSON.stringify({name: 'fresh', private: true, type: 'module'}));
  // The page's MapLibre (the plugin's pinned devDependency) as the peer: in npm's cache after `npm ci` here.
  const maplibre = `maplibre-gl@${manifest.devDependencies['maplibre-gl']}`;
  const tarball = join(work, packed.filename);
  run('npm', ['install', '--no-audit', '--no-fund', '--prefer-offline', '--loglevel=error', tarball, maplibre], project);
});

after(() => rmSync(work, {recursive: true, force: true}));

test('the tarball holds src/ (modules and declarations), the manifest and the README, nothing else', () => {
  const shipped = packed.files.map((f) => f.path).sort();
  const sources = readdirSync(join(PLUGIN, 'src')).map((name) => `src/${name}`);
  assert.deepEqual(shipped, ['README.md', 'package.json', ...sources].sort());
  assert.ok(shipped.includes('src/morph-worker.js'), 'the worker ships beside index.js (new URL resolves it)');
  assert.ok(shipped.includes(manifest.types), manifest.types);
  assert.ok(shipped.includes(manifest.exports['.'].types.replace(/^\.\//, '')));
  assert.ok(!shipped.some((p) => p.startsWith('test/') || p.startsWith('example/')));
});

test('a fresh project imports the installed package from node', () => {
  const probe = `
    import {CcsmMorph, MorphLayer, encodeMvt, tAt} from 'ccsm-morph';
    const morph = new CcsmMorph({tiles: ['https://example.org/{z}/{x}/{y}.mvt'], protocol: 'probe'});
    console.log(JSON.stringify({
      resolved: import.meta.resolve('ccsm-morph'),
      kinds: [typeof CcsmMorph, typeof MorphLayer, typeof encodeMvt],
      url: morph.tileUrl(352),
      t: tAt([0, 1], 0.25),
    }));`;
  const out = JSON.parse(run(process.execPath, ['--input-type=module', '-e', probe], project));
  assert.ok(out.resolved.startsWith(`file://${project}/node_modules/ccsm-morph/`), out.resolved);
  assert.deepEqual(out.kinds, ['function', 'function', 'function']);
  assert.equal(out.url, 'probe://step352/{z}/{x}/{y}');
  assert.equal(out.t, 0.25);
});

test("tsc type-checks the fresh project against the installed package's declarations", () => {
  writeFileSync(
    join(project, 'tsconfig.json'),
    JSON.stringify({
      compilerOptions: {
        target: 'ES2022',
        module: 'nodenext',
        moduleResolution: 'nodenext',
        lib: ['ES2022', 'DOM'],
        strict: true,
        noEmit: true,
        skipLibCheck: true,
        types: ['geojson'],
      },
      files: ['main.ts'],
    }),
  );
  writeFileSync(
    join(project, 'main.ts'),
    `import * as maplibregl from 'maplibre-gl';
import {CcsmMorph, type MorphLayer} from 'ccsm-morph';
const morph = new CcsmMorph({url: 'pmtiles://https://example.org/sample.pmtiles'}).setupMaplibre(maplibregl);
declare const map: maplibregl.Map;
const layer: MorphLayer = morph.addTo(map, {layers: [{id: 'lines', type: 'line', paint: {'line-color': '#8a4b1c'}}]});
const zoom: number | null = layer.shownZoom;
// @ts-expect-error: fadeSpan is a number
new CcsmMorph({url: '/morph/sample/tilejson.json', fadeSpan: 'an eighth'});
export {zoom};
`,
  );
  let listed;
  try {
    listed = run(TSC, ['-p', 'tsconfig.json', '--listFiles'], project);
  } catch (err) {
    assert.fail(`tsc failed in the fresh project:\n${err.stdout}${err.stderr}`);
  }
  const declarations = join(project, 'node_modules', 'ccsm-morph', manifest.types);
  assert.ok(listed.split('\n').includes(declarations), `tsc did not read ${declarations}`);
});
