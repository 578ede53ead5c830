// The README's example in TypeScript: `npm test` type-checks it (tsc --noEmit -p tsconfig.json) against
// src/index.d.ts, imported by the package's own name as a project that installed it would. Never run.
import * as maplibregl from 'maplibre-gl';
import {CcsmMorph, decodeMorphTile, renderMorphTile, tAt, type ContourProperties, type MorphLayer} from 'ccsm-morph';

// A morph TileJSON from the service, or 'pmtiles://https://example.org/sample.pmtiles' (a static archive).
const morph = new CcsmMorph({url: 'https://example.org/morph/sample/tilejson.json'}).setupMaplibre(maplibregl);
const map = new maplibregl.Map({container: 'map', style: 'https://example.org/style.json', center: [-84.25, 36.59], zoom: 11});
const contours: MorphLayer = morph.addTo(map, {
  id: 'contours',
  beforeId: 'place-labels', // optional: draw below this layer of your style
  layers: [{
    id: 'contour-lines',
    type: 'line',
    paint: {
      'line-color': '#8a4b1c',
      // index contours wider; a contour that appears inside a level grows in (morph_fade 0 -> 1)
      'line-width': ['*', ['case', ['get', 'index'], 1.8, 0.8], ['get', 'morph_fade']],
    },
  }],
  onChange: (state) => console.log(state.shownZoom ?? 'no tiles yet', state.settled),
  onError: (message: string) => console.error(message),
});

// The rest of the API as the README lists it.
const archive = new CcsmMorph({url: 'pmtiles://https://example.org/sample.pmtiles', stepsPerZoom: 16, fadeSpan: 0.25});
const fromTemplates = new CcsmMorph({tiles: ['https://example.org/morph/{z}/{x}/{y}.mvt'], minzoom: 8, maxzoom: 14});
const fromTileJson = new CcsmMorph({tilejson: {tiles: ['/morph/sample/{z}/{x}/{y}.mvt']}, cacheSize: 64, keepSamples: true});
const ids: string[] = contours.visibleLayerIds;
const shown: number | null = contours.shownZoom;
const settled: boolean = contours.settled;
contours.setOverride(11.5);
contours.setOverride(null);
const features = map.queryRenderedFeatures({layers: ids});
const elevations = features.map((f) => (f.properties as ContourProperties).elevation);
async function inspect(): Promise<number> {
  const meta = await archive.metadata();
  const tile = await fromTemplates.morphTile(meta.minzoom, 0, 0);
  const bytes: Uint8Array = renderMorphTile(decodeMorphTile(new ArrayBuffer(0)), 11, 11.5, {scale: 2});
  return tile.features.length + bytes.length + tAt([0, 0.5, 1], 0.5) + fromTileJson.fetchCount;
}
contours.remove();
morph.teardownMaplibre(maplibregl);

// Misuses the declarations must reject (tsc fails on an @ts-expect-error that sees no error).
// @ts-expect-error: stepsPerZoom is a number
new CcsmMorph({url: '/morph/sample/tilejson.json', stepsPerZoom: '32'});
// @ts-expect-error: a source is required (url, tilejson or tiles)
new CcsmMorph({stepsPerZoom: 32});
// @ts-expect-error: url and tiles are alternatives, not both
new CcsmMorph({url: '/morph/sample/tilejson.json', tiles: ['/morph/{z}/{x}/{y}.mvt']});
// @ts-expect-error: addTo needs `layers`
morph.addTo(map, {id: 'contours'});
// @ts-expect-error: the plugin's layers draw vector tiles, not rasters
morph.addTo(map, {layers: [{id: 'r', type: 'raster'}]});
// @ts-expect-error: the plugin's layers take no `source`
morph.addTo(map, {layers: [{id: 'l', type: 'line', source: 'other'}]});

export {elevations, inspect, settled, shown};
