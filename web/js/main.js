// ccsm web page: wires the controls, the maps and the morphing contour layers together.

import * as maplibregl from 'maplibre-gl';
import {getJSON, formatDetail} from './api.js';
import {installProtocol, onTileActivity} from './protocol.js';
import {MorphingContours} from './morph.js';
import {datasetLabel, initialDataset, tilejsonUrl} from './datasets.js';
import {tooltipText, tReadout, zoomReadout} from './readout.js';
import {formatScale, quantiseZoom, scaleDenominator} from './scale.js';
import {installDropZone, uploadDataset} from './upload.js';
import {comparisonLayers, contourLineLayers, contourSourceId, hillshadeOf, labelLayers, styleUrl} from './stylerules.js';

const METHOD_NAMES = {
  ccsm: 'CCSM',
  dp: 'Douglas–Peucker',
  wm: 'Wang–Müller',
  vw: 'Visvalingam–Whyatt',
  original: 'Original',
};
const COLOR_MAIN = '#8a4b1c';
const MORPH_FADE_SPAN = 0.5; // zoom levels over which a contour grows in at its min_zoom (morph_fade 0 -> 1)
const COLOR_COMPARE = '#1b63c6';

const $ = (id) => document.getElementById(id);
const params = new URLSearchParams(window.location.search);
// Captured before MapLibre writes the camera into the hash: a shared link keeps its view.
const initialHashHasCamera = /(^#|&)map=/.test(window.location.hash);

// Everything on this page that changes after it loads, in one place.
const app = {
  // What is chosen (window.ccsm.state).
  state: {
    datasetId: null,
    dataset: null,
    tilejson: null,
    method: params.get('method') ?? 'ccsm',
    compare: params.get('compare') ?? 'dp',
    view: params.get('view') ?? 'single',
    t: params.has('t') ? Number(params.get('t')) : null,
    // Hillshade under the contours (when the dataset has a DEM); ?hillshade=off starts without it.
    hillshade: params.get('hillshade') !== 'off',
    style: null, // the dataset's style.json (GET /styles/{id}/style.json), or null
  },
  // The ccsm-morph plugin's module (null when it could not be loaded: CCSM then uses the eighth-swap), and
  // the CcsmMorph of the dataset's morph tiles (null when the service has none for it).
  plugin: null,
  morph: null,
  errors: [], // every error text shown (window.ccsm.errors)
  maps: {a: null, b: null}, // b: the split view's second map, made when first needed
  layers: {main: null, overlay: null, split: null},
  syncing: false, // true while one split map moves the other
  readoutQueued: false,
  tStatsTimer: null,
  lastTStats: null,
  datasetList: [],
  listPoll: null,
  lineLayers: null, // the contour line layers of the dataset's style (every method draws them), or null
  labelLayerIds: new Map(), // map -> ids of the label layers of the dataset's style drawn on it
  mapBLoaded: false,
  pointer: null, // {map, point, clientX, clientY} of the mouse over a map, for the tooltip (null: off the maps)
};
const {state} = app;

// ---------------------------------------------------------------- messages

function showMessage(text, kind = 'error', {timeoutMs = 0} = {}) {
  const box = document.createElement('div');
  box.className = `message ${kind}`;
  const p = document.createElement('p');
  p.textContent = text;
  const close = document.createElement('button');
  close.type = 'button';
  close.setAttribute('aria-label', 'Dismiss');
  close.textContent = '×';
  close.onclick = () => box.remove();
  box.append(p, close);
  $('messages').append(box);
  if (kind === 'error') app.errors.push(text);
  if (timeoutMs) setTimeout(() => box.remove(), timeoutMs);
  return box;
}

function showError(err) {
  const text = typeof err === 'string' ? err : err?.message ?? formatDetail(err);
  // Repeated tile errors would flood the corner: show each text once at a time.
  for (const m of $('messages').querySelectorAll('.message.error p')) if (m.textContent === text) return;
  showMessage(text, 'error');
}

// ---------------------------------------------------------------- base style (offline: the service's own glyphs, no sprites)

const HILLSHADE_SOURCE = 'page-hillshade';
const HILLSHADE_LAYER = 'page-hillshade';
const LABEL_SOURCE = 'page-labels';

function baseStyle() {
  return {
    version: 8,
    // The label font comes from the service itself (GET /fonts/...), never from outside.
    glyphs: `${window.location.origin}/fonts/{fontstack}/{range}.pbf`,
    // No cross-fades: a swapped-in buffer must appear in the same frame the old one goes.
    transition: {duration: 0, delay: 0},
    sources: {extent: {type: 'geojson', data: {type: 'FeatureCollection', features: []}}},
    layers: [
      {id: 'background', type: 'background', paint: {'background-color': '#f4f1ea'}},
      {id: 'extent-fill', type: 'fill', source: 'extent', paint: {'fill-color': '#ffffff', 'fill-opacity': 0.55}},
      {
        id: 'extent-line',
        type: 'line',
        source: 'extent',
        paint: {'line-color': '#a09a8e', 'line-width': 1, 'line-dasharray': [3, 2]},
      },
      // Empty anchors: contour layers go below them, so the compared method draws over the main one.
      {id: 'anchor-main', type: 'background', layout: {visibility: 'none'}},
      {id: 'anchor-compare', type: 'background', layout: {visibility: 'none'}},
    ],
  };
}

function createMap(container) {
  return new maplibregl.Map({
    container,
    style: baseStyle(),
    center: [0, 0],
    zoom: 1,
    hash: container === 'map-a' ? 'map' : false,
    attributionControl: {compact: true},
    // Labels that MapLibre's collision test hides or shows fade over this time instead of popping.
    fadeDuration: 300,
    maxPitch: 0,
    dragRotate: false,
    // Playwright screenshots read the composited page, so preserveDrawingBuffer is not needed.
  });
}

// ---------------------------------------------------------------- maps and layers

function whenStyleLoaded(map) {
  return map.isStyleLoaded() ? Promise.resolve() : new Promise((resolve) => map.once('load', resolve));
}

function layerCallbacks() {
  return {onChange: () => scheduleReadout(), onError: (msg) => showError(msg)};
}

function ensureMapB() {
  const {maps} = app;
  if (maps.b) return maps.b;
  maps.b = createMap('map-b');
  app.layers.split = new MorphingContours(maps.b, {color: COLOR_MAIN, beforeId: 'anchor-main', ...layerCallbacks()});
  wireMap(maps.b);
  const sync = (from, to) => () => {
    if (app.syncing || !to) return;
    app.syncing = true;
    to.jumpTo({center: from.getCenter(), zoom: from.getZoom(), bearing: from.getBearing(), pitch: from.getPitch()});
    app.syncing = false;
  };
  maps.a.on('move', sync(maps.a, maps.b));
  maps.b.on('move', sync(maps.b, maps.a));
  maps.b.on('load', () => {
    app.mapBLoaded = true;
    maps.b.jumpTo({center: maps.a.getCenter(), zoom: maps.a.getZoom()});
    drawCartography(maps.b, state.style);
    app.layers.split.setStyleLayers(app.lineLayers);
    applyView();
  });
  return maps.b;
}

function wireMap(map) {
  map.on('move', scheduleReadout);
  // The tooltip describes what is under the mouse now: it goes while the map moves (the contour under it
  // changes, or morphs) and comes back, read anew, once the map is idle again.
  map.on('move', hideTooltip);
  map.on('idle', () => app.pointer?.map === map && hover(map, app.pointer));
  map.on('mousemove', (e) => {
    app.pointer = {map, point: e.point, clientX: e.originalEvent.clientX, clientY: e.originalEvent.clientY};
    if (!map.isMoving()) hover(map, app.pointer);
  });
  map.on('mouseout', () => {
    app.pointer = null;
    hideTooltip();
  });
  map.on('error', (e) => {
    // Tile errors of our sources are reported by MorphingContours; anything else is shown here.
    if (e.sourceId && /^m\d+-src-/.test(e.sourceId)) return;
    const message = e.error?.message ?? String(e.error ?? 'map error');
    if (!/abort/i.test(message)) showError(`Map: ${message}`);
  });
}

function setExtent(map, bounds) {
  const src = map.getSource('extent');
  if (!src) return;
  if (!bounds) {
    src.setData({type: 'FeatureCollection', features: []});
    return;
  }
  const [w, s, e, n] = bounds;
  src.setData({
    type: 'Feature',
    properties: {},
    geometry: {type: 'Polygon', coordinates: [[[w, s], [e, s], [e, n], [w, n], [w, s]]]},
  });
}

/** Apply view, methods and t to every layer set. */
function applyView() {
  const tj = state.tilejson;
  const {maps, layers} = app;
  const panes = $('maps');
  panes.classList.remove('single', 'split', 'overlay');
  panes.classList.add(state.view);
  $('compare-field').classList.toggle('hidden-field', state.view === 'single');
  $('label-a').textContent = METHOD_NAMES[state.method];
  $('label-b').textContent = METHOD_NAMES[state.compare];
  hideTooltip(); // it named the method or view that was shown: read anew when the map is idle

  const {morph} = app;
  layers.main.setOptions({method: state.method, t: state.t, morph});
  if (layers.main.tilejson !== tj) layers.main.setDataset(tj);

  const overlayOn = state.view === 'overlay' && tj;
  layers.overlay.setOptions({method: state.compare, t: state.t, morph});
  if (layers.overlay.tilejson !== (overlayOn ? tj : null)) layers.overlay.setDataset(overlayOn ? tj : null);

  const splitOn = state.view === 'split';
  const paneWasHidden = $('pane-b').hidden;
  $('pane-b').hidden = !splitOn;
  if (splitOn) ensureMapB();
  maps.a.resize();
  if (maps.b) {
    if (splitOn && paneWasHidden) maps.b.jumpTo({center: maps.a.getCenter(), zoom: maps.a.getZoom()});
    maps.b.resize();
    if (app.mapBLoaded) {
      setExtent(maps.b, tj?.bounds);
      layers.split.setOptions({method: state.compare, t: state.t, morph});
      const want = splitOn && tj ? tj : null;
      if (layers.split.tilejson !== want) layers.split.setDataset(want);
    }
  }
  renderLegend();
  scheduleReadout();
}

/** The legend: the method of each pane (split), or of each line colour (overlay), or the one method shown. */
function renderLegend() {
  const legend = $('legend');
  if (!state.tilejson) {
    legend.hidden = true;
    return;
  }
  legend.hidden = false;
  const main = METHOD_NAMES[state.method];
  const compare = METHOD_NAMES[state.compare];
  const rows = {
    single: [[COLOR_MAIN, main, '']],
    split: [[COLOR_MAIN, `Left: ${main}`, ''], [COLOR_MAIN, `Right: ${compare}`, '']],
    overlay: [[COLOR_MAIN, main, ''], [COLOR_COMPARE, `${compare} (thin, on top)`, ' thin']],
  }[state.view] ?? [[COLOR_MAIN, main, '']];
  legend.replaceChildren(
    ...rows.map(([color, name, kind]) => {
      const div = document.createElement('div');
      const sw = document.createElement('span');
      sw.className = `swatch${kind}`;
      sw.style.borderTopColor = color;
      div.append(sw, name);
      return div;
    }),
  );
}

// ---------------------------------------------------------------- readout and hover

function scheduleReadout() {
  if (app.readoutQueued) return;
  app.readoutQueued = true;
  requestAnimationFrame(() => {
    app.readoutQueued = false;
    updateReadout();
  });
  clearTimeout(app.tStatsTimer);
  app.tStatsTimer = setTimeout(() => {
    app.lastTStats = app.layers.main?.visibleTStats() ?? null;
    updateReadout();
  }, 150);
}

function updateReadout() {
  const mapA = app.maps.a;
  if (!mapA) return;
  const zoom = mapA.getZoom();
  const lat = mapA.getCenter().lat;
  $('readout-scale').textContent = formatScale(scaleDenominator(zoom, lat));
  const s = app.layers.main?.state();
  $('readout-zoom').textContent = zoomReadout(zoom, s?.activeQ);
  $('readout-t').textContent = tReadout(state.t, state.method, app.lastTStats);
}

function hideTooltip() {
  $('tooltip').hidden = true;
  for (const map of Object.values(app.maps)) if (map) map.getCanvas().style.cursor = '';
}

/** Show what lies under the mouse (`at`: {point, clientX, clientY} on `map`), named by the method drawing it. */
function hover(map, at) {
  const layers = allLayers().filter((l) => l && l.map === map);
  const ids = layers.flatMap((l) => l.visibleLayerIds);
  const tip = $('tooltip');
  if (!ids.length) {
    hideTooltip();
    return;
  }
  const {x, y} = at.point;
  const features = map.queryRenderedFeatures([[x - 4, y - 4], [x + 4, y + 4]], {layers: ids});
  if (!features.length) {
    hideTooltip();
    return;
  }
  const f = features[0];
  const owner = layers.find((l) => l.visibleLayerIds.includes(f.layer.id));
  tip.textContent = tooltipText(f.properties, METHOD_NAMES[owner?.method] ?? '');
  tip.style.left = `${at.clientX + 12}px`;
  tip.style.top = `${at.clientY + 12}px`;
  tip.hidden = false;
  map.getCanvas().style.cursor = 'crosshair';
}

// ---------------------------------------------------------------- datasets

async function refreshDatasets() {
  const datasetList = await getJSON('/datasets', 'Listing datasets');
  app.datasetList = datasetList;
  const select = $('dataset');
  select.replaceChildren(
    ...datasetList.map((ds) => {
      const opt = document.createElement('option');
      opt.value = ds.id;
      opt.textContent = datasetLabel(ds);
      opt.disabled = ds.state !== 'ready';
      return opt;
    }),
  );
  if (state.datasetId) select.value = state.datasetId;
  // Keep the list fresh while something builds (an upload from another tab, the sample at start-up).
  clearTimeout(app.listPoll);
  if (datasetList.some((d) => d.state === 'building')) {
    app.listPoll = setTimeout(() => refreshDatasets().then(pickInitialDataset).catch(showError), 1500);
  }
  return datasetList;
}

function pickInitialDataset() {
  if (state.datasetId) return;
  const ds = initialDataset(app.datasetList, params.get('dataset'));
  if (ds) selectDataset(ds.id, {fit: !initialHashHasCamera}).catch(showError);
}

async function selectDataset(id, {fit = true} = {}) {
  const listed = app.datasetList.find((d) => d.id === id) ?? {id};
  const [ds, tj] = await Promise.all([
    getJSON(`/datasets/${encodeURIComponent(id)}`, `Dataset “${listed.name ?? id}”`),
    getJSON(tilejsonUrl(listed), `TileJSON of “${listed.name ?? id}”`),
  ]);
  if (!Array.isArray(tj.tiles) || !tj.tiles.length) throw new Error(`TileJSON of “${id}” lists no tiles URL`);
  const [morph, style] = await Promise.all([morphFor(id), styleFor(id)]);
  if (app.morph) app.morph.teardownMaplibre(maplibregl);
  app.morph = morph;
  state.datasetId = id;
  state.dataset = ds;
  state.tilejson = tj;
  state.style = style;
  $('dataset').value = id;
  const mapA = app.maps.a;
  await whenStyleLoaded(mapA);
  setExtent(mapA, tj.bounds);
  applyStyle(style);
  if (fit) {
    if (tj.bounds) mapA.fitBounds(tj.bounds, {padding: 30, animate: false});
    else if (tj.center) mapA.jumpTo({center: [tj.center[0], tj.center[1]], zoom: tj.center[2] ?? 10});
  }
  applyView();
}

/**
 * A CcsmMorph for the dataset's morph tiles (GET /morph/{id}/tilejson.json), or null when the plugin did not
 * load or the service has no morph tiles for it; CCSM then falls back to the eighth-swap.
 */
async function morphFor(id) {
  // ?morph=off keeps the eighth-swap for CCSM too (comparisons, bench/bench_morph.py).
  if (!app.plugin || params.get('morph') === 'off') return null;
  let tilejson;
  try {
    const response = await fetch(`/morph/${encodeURIComponent(id)}/tilejson.json`);
    if (!response.ok) return null;
    tilejson = await response.json();
  } catch {
    return null;
  }
  if (!Array.isArray(tilejson.tiles) || !tilejson.tiles.length) return null;
  // A contour that CCSM lets vanish at its scale (min_zoom) fades over half a level, like the style's ranks
  // fade over theirs: a wheel step of about 0.2 zoom never takes it from full width to nothing at once.
  return new app.plugin.CcsmMorph({tilejson, fadeSpan: MORPH_FADE_SPAN}).setupMaplibre(maplibregl);
}

/** The dataset's style.json, or null when the service has none for it (the page then draws plain lines). */
async function styleFor(id) {
  try {
    const response = await fetch(styleUrl(id));
    return response.ok ? await response.json() : null;
  } catch {
    return null;
  }
}

/**
 * Draw a dataset the way its style.json says, whichever method each layer shows: the contour lines by rank
 * with their fade and index weight (through the morphing layers; the overlay's compared method as a thin line
 * of its own colour), and on each map the hillshade under everything and the labels on top.
 */
function applyStyle(style) {
  const lines = style ? contourLineLayers(style) : null;
  app.lineLayers = lines;
  const {main, overlay, split} = app.layers;
  main.setStyleLayers(lines);
  overlay.setStyleLayers(lines ? comparisonLayers(lines, COLOR_COMPARE) : null);
  $('hillshade-field').hidden = !hillshadeOf(style);
  drawCartography(app.maps.a, style);
  if (app.mapBLoaded) {
    split.setStyleLayers(lines);
    drawCartography(app.maps.b, style);
  }
}

/** The style's hillshade (under the contours) and labels (from the per-level tiles) on one map. */
function drawCartography(map, style) {
  for (const id of app.labelLayerIds.get(map) ?? []) if (map.getLayer(id)) map.removeLayer(id);
  app.labelLayerIds.set(map, []);
  if (map.getLayer(HILLSHADE_LAYER)) map.removeLayer(HILLSHADE_LAYER);
  for (const id of [HILLSHADE_SOURCE, LABEL_SOURCE]) if (map.getSource(id)) map.removeSource(id);
  if (!style) return;
  const hillshade = hillshadeOf(style);
  if (hillshade) {
    map.addSource(HILLSHADE_SOURCE, hillshade.source);
    const layout = {...hillshade.layer.layout, visibility: state.hillshade ? 'visible' : 'none'};
    map.addLayer({...hillshade.layer, id: HILLSHADE_LAYER, source: HILLSHADE_SOURCE, layout}, 'extent-line');
  }
  const contours = style.sources?.[contourSourceId(style)];
  if (contours) {
    map.addSource(LABEL_SOURCE, {...contours});
    for (const layer of labelLayers(style, LABEL_SOURCE)) {
      map.addLayer(layer);
      app.labelLayerIds.get(map).push(layer.id);
    }
  }
}

async function handleFile(file) {
  const bar = $('upload-bar');
  const label = $('upload-label');
  $('upload-progress').hidden = false;
  label.textContent = `Uploading ${file.name}…`;
  bar.removeAttribute('value');
  try {
    const ds = await uploadDataset(file, {
      scales: {
        source_scale: $('upload-source-scale').value.trim(),
        target_scale: $('upload-target-scale').value.trim(),
      },
      onProgress: (d, fraction) => {
        label.textContent = `Building ${d.name ?? file.name}: ${fraction == null ? '…' : `${Math.round(fraction * 100)} %`}`;
        if (fraction == null) bar.removeAttribute('value');
        else bar.value = fraction;
      },
    });
    label.textContent = `${ds.name ?? file.name} is ready`;
    bar.value = 1;
    await refreshDatasets();
    await selectDataset(ds.id, {fit: true});
    showMessage(`Dataset “${ds.name ?? file.name}” is ready.`, 'info', {timeoutMs: 4000});
    setTimeout(() => ($('upload-progress').hidden = true), 1500);
  } catch (err) {
    $('upload-progress').hidden = true;
    showError(err);
  }
}

// ---------------------------------------------------------------- controls

function wireControls() {
  $('method').value = state.method;
  $('compare').value = state.compare;
  $('view').value = state.view;
  $('method').onchange = (e) => {
    state.method = e.target.value;
    applyView();
  };
  $('compare').onchange = (e) => {
    state.compare = e.target.value;
    applyView();
  };
  $('view').onchange = (e) => {
    state.view = e.target.value;
    applyView();
  };
  $('dataset').onchange = (e) => selectDataset(e.target.value).catch(showError);
  const pin = $('t-pin');
  const slider = $('t-slider');
  const out = $('t-value');
  const applyT = () => {
    state.t = pin.checked ? Number(slider.value) : null;
    slider.disabled = !pin.checked;
    out.textContent = pin.checked ? Number(slider.value).toFixed(2) : 'auto';
    applyView();
  };
  if (state.t != null) {
    pin.checked = true;
    slider.value = String(state.t);
  }
  const hillshade = $('hillshade');
  hillshade.checked = state.hillshade;
  hillshade.onchange = () => {
    state.hillshade = hillshade.checked;
    for (const map of Object.values(app.maps)) {
      if (map?.getLayer(HILLSHADE_LAYER)) map.setLayoutProperty(HILLSHADE_LAYER, 'visibility', state.hillshade ? 'visible' : 'none');
    }
  };
  pin.onchange = applyT;
  slider.oninput = applyT;
  applyT();
  $('upload-button').onclick = () => $('upload-input').click();
  $('upload-input').onchange = (e) => {
    const file = e.target.files?.[0];
    e.target.value = '';
    if (file) handleFile(file);
  };
  installDropZone($('dropzone'), handleFile);
  onTileActivity((n) => ($('readout-net').textContent = n ? `loading ${n} tile${n > 1 ? 's' : ''}` : ''));
}

// ---------------------------------------------------------------- test and console hooks

function allLayers() {
  const {main, overlay, split} = app.layers;
  return [main, overlay, split];
}

function layersInUse() {
  return allLayers().filter((l) => l && l.tilejson);
}

window.ccsm = {
  maplibregl,
  state,
  errors: app.errors,
  get maps() {
    return {...app.maps};
  },
  get layers() {
    return {...app.layers};
  },
  quantiseZoom,
  selectDataset: (id, opts) => selectDataset(id, opts),
  refreshDatasets: () => refreshDatasets(),
  /** Fix the morph zoom of every layer (null follows the map again). */
  setMorphOverride(q) {
    for (const l of allLayers()) l?.setOverride(q);
  },
  /** True when every layer in use shows what the camera and controls ask for and all its tiles are in, the
   *  label and hillshade tiles of map a included (they come from sources of their own, which load apart). */
  settled() {
    const used = layersInUse();
    if (!state.tilejson || !used.length) return false;
    const maps = [app.maps.a, state.view === 'split' ? app.maps.b : null].filter(Boolean);
    for (const map of maps) {
      for (const id of [LABEL_SOURCE, HILLSHADE_SOURCE]) {
        if (map.getSource(id) && !map.isSourceLoaded(id)) return false;
      }
    }
    return used.every((l) => {
      if (!l.settled || l.map.isMoving()) return false;
      try {
        return l.map.isSourceLoaded(l.active.sourceId);
      } catch {
        return false;
      }
    });
  },
  layerStates: () => layersInUse().map((l) => l.state()),
  /** The ids of the label layers and of the hillshade layer on map a (the dataset's style.json). */
  get cartography() {
    return this.cartographyOf('a');
  },
  /** The same on map `name` ('a', or 'b' of the split view). */
  cartographyOf(name) {
    const map = app.maps[name];
    const labelLayerIds = [...(app.labelLayerIds.get(map) ?? [])];
    return {labelLayerIds, hillshadeLayerId: map?.getLayer(HILLSHADE_LAYER) ? HILLSHADE_LAYER : null};
  },
  /** The CcsmMorph of the dataset (null: no morph tiles, or the plugin is not loaded). */
  get morph() {
    return app.morph;
  },
};

// ---------------------------------------------------------------- start

async function start() {
  installProtocol();
  // The plugin is loaded on its own, so the page still works (with the eighth-swap) if it cannot be.
  app.plugin = await import('ccsm-morph').catch((err) => {
    console.warn('ccsm-morph did not load; CCSM uses the eighth-swap', err);
    return null;
  });
  try {
    app.maps.a = createMap('map-a');
  } catch (err) {
    // Without WebGL2 MapLibre throws here ("WebGL2 is required ...") and would never fire load/idle.
    const boot = $('boot');
    boot.textContent = `This map needs WebGL2, which this browser does not provide: ${err?.message ?? err}`;
    boot.classList.add('failed');
    showError(boot.textContent);
    window.ccsm.failed = boot.textContent;
    return;
  }
  const mapA = app.maps.a;
  app.layers.main = new MorphingContours(mapA, {color: COLOR_MAIN, beforeId: 'anchor-main', ...layerCallbacks()});
  app.layers.overlay = new MorphingContours(mapA, {
    color: COLOR_COMPARE,
    beforeId: 'anchor-compare',
    dasharray: [3, 2],
    ...layerCallbacks(),
  });
  wireMap(mapA);
  mapA.addControl(new maplibregl.NavigationControl({showCompass: false}), 'top-left');
  wireControls();
  await whenStyleLoaded(mapA);
  $('boot').remove();
  await refreshDatasets();
  if (!app.datasetList.length) showMessage('No datasets yet: drop a GeoJSON contour file on the map.', 'info');
  else if (!app.datasetList.some((d) => d.state === 'ready')) showMessage('The dataset is still being built…', 'info', {timeoutMs: 5000});
  pickInitialDataset();
}

window.ccsm.ready = start().catch((err) => {
  showError(err);
  window.ccsm.failed = err?.message ?? String(err);
});
