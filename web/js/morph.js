// Continuous morphing by double-buffered vector sources.
//
// The map zoom is quantised to eighths, q = floor(zoom * 8) / 8. Each q (with the method and the pinned t) is
// one MapLibre vector source whose tiles ask the service for `zoom=q`. When q changes we never call setTiles on
// the visible source (that blanks it): a new "pending" source is added with its layers at opacity 0, and once
// all its tiles in view have arrived the layers are switched to their own opacity (the style's fade) and the old
// source is removed in the same frame. So the old geometry stays on screen until the new geometry is ready.
// Every buffer draws the dataset style's line layers (setStyleLayers), whichever method it shows.
//
// Overtaken loads: if q moves on while a pending source is still loading, the pending source is removed, which
// makes MapLibre abort its tile requests (our protocol's AbortController). A pending load that has been running
// for MIN_PROGRESS_MS is allowed to finish first, so a long continuous gesture still shows intermediate shapes
// instead of waiting for the gesture to end.
//
// CCSM with t following the zoom is drawn by the ccsm-morph plugin instead when the dataset has morph tiles
// (setOptions({morph})): each morph tile is fetched once and the plugin draws 32 steps per zoom level from
// memory (web/plugin/README.md). The eighth-swap above stays for the baselines and for a pinned t.

import {clampMorphZoom, quantiseZoom} from './scale.js';
import {registerSource, unregisterSource} from './protocol.js';

export const MIN_PROGRESS_MS = 150;
const SOURCE_LAYER = 'contours';

let instanceCounter = 0;

/** Median and range of the `t` field over features. */
export function tStats(features) {
  const ts = features.map((f) => Number(f.properties?.t)).filter(Number.isFinite).sort((a, b) => a - b);
  if (!ts.length) return null;
  return {min: ts[0], max: ts[ts.length - 1], median: ts[Math.floor(ts.length / 2)], count: ts.length};
}

export class MorphingContours {
  /**
   * @param {import('maplibre-gl').Map} map
   * @param {object} options  color, beforeId (anchor layer), label (for the tooltip), onChange(state), onError(msg)
   */
  constructor(map, {color = '#8a4b1c', beforeId = undefined, label = '', dasharray = null, onChange, onError} = {}) {
    this.map = map;
    this.id = `m${++instanceCounter}`;
    this.color = color;
    this.dasharray = dasharray;
    this.beforeId = beforeId;
    this.label = label;
    this.onChange = onChange ?? (() => {});
    this.onError = onError ?? (() => {});
    this.tilejson = null;
    this.method = 'ccsm';
    this.t = null; // null: the service picks t from the zoom (the morph); a number pins it
    this.override = null; // a fixed morph zoom (tests, debugging); null follows the map
    this._active = null;
    this.pending = null;
    this.swaps = 0;
    this.cancelled = 0;
    this._counter = 0;
    this.morph = null; // a CcsmMorph of the dataset's morph tiles, or null
    this._plugin = null; // the plugin's MorphLayer while it draws this layer
    this.styleLayers = null; // the dataset style's contour line layers every buffer draws (null: plain lines)
    this._pluginSwaps = 0;
    this._handlers = {
      render: () => this.update(),
      idle: () => this._checkPending(),
      sourcedata: (e) => this._onSourceData(e),
      error: (e) => this._onMapError(e),
    };
    for (const [name, fn] of Object.entries(this._handlers)) map.on(name, fn);
    // Not map.isStyleLoaded(): that is false while any source loads, i.e. whenever a buffer is pending.
    this._styleReady = map.isStyleLoaded();
    if (!this._styleReady) {
      map.once('load', () => {
        this._styleReady = true;
        this.update();
      });
    }
  }

  /**
   * What is on screen: {q, key, method, t, sourceId, layerIds} of the visible buffer (the eighth-swap's own,
   * or the plugin's), or null.
   */
  get active() {
    const p = this._plugin;
    if (!p) return this._active;
    if (!p.active) return null;
    const q = p.shownZoom;
    return {q, key: this.keyFor(q), method: 'ccsm', t: null, sourceId: p.active.sourceId, layerIds: p.visibleLayerIds};
  }

  /** True when the plugin draws this layer (CCSM following the zoom, and the dataset has morph tiles). */
  get usesPlugin() {
    return Boolean(this.morph && this.tilejson && this.method === 'ccsm' && this.t === null);
  }

  /** The layer ids of the geometry currently on screen (for queryRenderedFeatures). */
  get visibleLayerIds() {
    const active = this.active;
    return active ? active.layerIds.filter((id) => this.map.getLayer(id)) : [];
  }

  get desiredQ() {
    if (!this.tilejson) return null;
    if (this._plugin) return this._plugin.desiredStep() / this.morph.stepsPerZoom;
    const q = this.override ?? quantiseZoom(this.map.getZoom());
    return clampMorphZoom(q, this.tilejson.minzoom ?? 0, this.tilejson.maxzoom ?? 22);
  }

  keyFor(q) {
    return `${this.method}|${this.t ?? 'auto'}|${q}`;
  }

  setDataset(tilejson) {
    this._removePlugin();
    this._removeBuffer(this.pending);
    this._removeBuffer(this._active);
    this.pending = null;
    this._active = null;
    this.tilejson = tilejson;
    this.update();
  }

  setOptions({method = this.method, t = this.t, morph = this.morph} = {}) {
    this.method = method;
    this.t = t;
    if (morph !== this.morph) this._removePlugin();
    this.morph = morph;
    this.update();
  }

  /**
   * Draw with these style layers (the dataset's style.json line layers, without a source: see stylerules.js)
   * instead of the two plain ones, both the continuous morph and the eighth-swap of every other method; null
   * goes back to the plain ones.
   */
  setStyleLayers(layers) {
    const next = layers?.length ? layers : null;
    if (next === this.styleLayers) return;
    this.styleLayers = next;
    this._removePlugin();
    this._removeBuffer(this.pending);
    this._removeBuffer(this._active);
    this.pending = null;
    this._active = null;
    this.update();
  }

  setOverride(q) {
    this.override = q;
    this._plugin?.setOverride(q);
    this.update();
  }

  /** True when what is on screen is what the current camera and options ask for. */
  get settled() {
    if (this.usesPlugin) return Boolean(this._plugin?.settled);
    return !this.tilejson || (!this.pending && this._active?.key === this.keyFor(this.desiredQ));
  }

  state() {
    return {
      method: this.method,
      t: this.t,
      desiredQ: this.desiredQ,
      activeQ: this.active?.q ?? null,
      pendingQ: this._plugin ? this._plugin.state().pendingZoom : (this.pending?.q ?? null),
      plugin: Boolean(this._plugin),
      swaps: this.swaps,
      cancelled: this.cancelled,
      settled: this.settled,
    };
  }

  /** Called every rendered frame: start loading a new buffer when the wanted key changes. */
  update() {
    if (!this.tilejson || !this._styleReady) return;
    if (this.usesPlugin) {
      if (!this._plugin) this._startPlugin();
      return;
    }
    this._removePlugin();
    const q = this.desiredQ;
    const key = this.keyFor(q);
    if (this.pending) {
      if (this.pending.key === key) return this._checkPending();
      if (performance.now() - this.pending.started >= MIN_PROGRESS_MS) return this._checkPending();
      // Overtaken: removing the source aborts its tile requests.
      this._removeBuffer(this.pending);
      this.pending = null;
      this.cancelled += 1;
    }
    if (this._active?.key === key) return;
    this.pending = this._addBuffer(q, key, !this._active);
    this.onChange(this.state());
  }

  _startPlugin() {
    // The eighth-swap's buffers go: the plugin draws from now on.
    this._removeBuffer(this.pending);
    this._removeBuffer(this._active);
    this.pending = null;
    this._active = null;
    const dash = this.dasharray ? {'line-dasharray': this.dasharray} : {};
    // A contour that appears inside a level (min_zoom) grows in: morph_fade runs from 0 to 1 over 1/8 level.
    const width = (w) => ['*', w, ['coalesce', ['get', 'morph_fade'], 1]];
    const base = {type: 'line', layout: {'line-join': 'round', 'line-cap': 'round'}};
    const id = `${this.id}-src-ccsm`;
    this._pluginSwaps = 0;
    this._plugin = this.morph.addTo(this.map, {
      id,
      beforeId: this.beforeId,
      layers: this.styleLayers?.map((l) => ({...l, id: `${id}-${l.id}`})) ?? [
        {
          ...base,
          id: `${id}-line`,
          filter: ['!', ['to-boolean', ['get', 'index']]],
          paint: {'line-color': this.color, 'line-width': width(0.8), ...dash},
        },
        {
          ...base,
          id: `${id}-index`,
          filter: ['to-boolean', ['get', 'index']],
          paint: {'line-color': this.color, 'line-width': width(1.8), ...dash},
        },
      ],
      onChange: (s) => {
        this.swaps += s.swaps - this._pluginSwaps;
        this._pluginSwaps = s.swaps;
        this.onChange(this.state());
      },
      onError: (message) => this.onError(message),
    });
    if (this.override !== null) this._plugin.setOverride(this.override);
    this.onChange(this.state());
  }

  _removePlugin() {
    if (!this._plugin) return;
    this._plugin.remove();
    this._plugin = null;
  }

  _addBuffer(q, key, firstBuffer) {
    const n = ++this._counter;
    const sourceId = `${this.id}-src-${n}`;
    const {key: protocolKey, url} = registerSource({
      template: this.tilejson.tiles[0],
      q,
      method: this.method,
      t: this.t,
    });
    const tj = this.tilejson;
    const source = {type: 'vector', tiles: [url], minzoom: tj.minzoom ?? 0, maxzoom: tj.maxzoom ?? 22};
    if (tj.bounds) source.bounds = tj.bounds;
    if (tj.attribution) source.attribution = tj.attribution;
    this.map.addSource(sourceId, source);
    const specs = this._bufferLayers(sourceId);
    // A buffer being loaded is drawn at opacity 0 (a hidden layer would load no tiles); its own opacity (the
    // style's fade, or 1) is put back when it is swapped in.
    const opacities = specs.map((l) => l.paint['line-opacity'] ?? 1);
    const layers = specs.map((l, i) => ({...l, paint: {...l.paint, 'line-opacity': firstBuffer ? opacities[i] : 0}}));
    for (const layer of layers) this.map.addLayer(layer, this.beforeId);
    return {
      sourceId,
      protocolKey,
      layerIds: layers.map((l) => l.id),
      opacities,
      q,
      key,
      method: this.method,
      t: this.t,
      started: performance.now(),
      sawTile: false,
    };
  }

  /**
   * The line layers of one eighth-swap buffer: the dataset style's (setStyleLayers), so every method is drawn
   * with the same rank fades and index weight as CCSM; without a style, two plain ones (index heavier).
   */
  _bufferLayers(sourceId) {
    const base = {source: sourceId, 'source-layer': SOURCE_LAYER};
    if (this.styleLayers) {
      return this.styleLayers.map((l) => ({...l, ...base, id: `${sourceId}-${l.id}`, paint: {...l.paint}}));
    }
    const plain = {...base, type: 'line', layout: {'line-join': 'round', 'line-cap': 'round'}};
    const dash = this.dasharray ? {'line-dasharray': this.dasharray} : {};
    return [
      {
        ...plain,
        id: `${sourceId}-line`,
        filter: ['!', ['to-boolean', ['get', 'index']]],
        paint: {'line-color': this.color, 'line-width': 0.8, ...dash},
      },
      {
        ...plain,
        id: `${sourceId}-index`,
        filter: ['to-boolean', ['get', 'index']],
        paint: {'line-color': this.color, 'line-width': 1.8, ...dash},
      },
    ];
  }

  _removeBuffer(buffer) {
    if (!buffer) return;
    for (const id of buffer.layerIds) if (this.map.getLayer(id)) this.map.removeLayer(id);
    if (this.map.getSource(buffer.sourceId)) this.map.removeSource(buffer.sourceId);
    unregisterSource(buffer.protocolKey);
  }

  _onSourceData(e) {
    if (!this.pending || e.sourceId !== this.pending.sourceId) return;
    // 'metadata'/'content' events come before any tile is even wanted; only a tile event counts.
    if (e.tile) this.pending.sawTile = true;
    this._checkPending();
  }

  _onMapError(e) {
    const buffers = [this.pending, this._active].filter(Boolean);
    if (e.sourceId && !buffers.some((b) => b.sourceId === e.sourceId)) return;
    if (!e.sourceId) return;
    const message = e.error?.message ?? String(e.error ?? 'tile error');
    if (/abort/i.test(message)) return;
    this.onError(message);
  }

  _checkPending() {
    const p = this.pending;
    if (!p || !this.map.getSource(p.sourceId)) return;
    let loaded;
    try {
      loaded = this.map.isSourceLoaded(p.sourceId);
    } catch {
      loaded = false;
    }
    // Right after addSource no tile is wanted yet and the source counts as loaded; wait for a tile, unless the
    // map is idle (then nothing is in view and there is nothing to wait for).
    if (!loaded || !(p.sawTile || this.map.loaded())) return;
    this._swap();
  }

  _swap() {
    const p = this.pending;
    p.layerIds.forEach((id, i) => this.map.setPaintProperty(id, 'line-opacity', p.opacities[i]));
    const old = this._active;
    this._active = p;
    this.pending = null;
    this._removeBuffer(old);
    this.swaps += 1;
    this.onChange(this.state());
    // The camera may have moved on while this buffer loaded.
    this.update();
  }

  /** t of the features on screen (from the service's `t` field, or the plugin's t at the drawn zoom). */
  visibleTStats() {
    const active = this.active;
    if (!active || !this.map.getSource(active.sourceId)) return null;
    return tStats(this.map.querySourceFeatures(active.sourceId, {sourceLayer: SOURCE_LAYER}));
  }

  destroy() {
    for (const [name, fn] of Object.entries(this._handlers)) this.map.off(name, fn);
    this._removePlugin();
    this._removeBuffer(this.pending);
    this._removeBuffer(this._active);
    this.pending = null;
    this._active = null;
  }
}
