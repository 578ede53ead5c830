// One map's morphing contours: two vector sources ("buffers") fed by the plugin's protocol, each with a copy
// of the caller's style layers. The visible buffer shows step k of the zoom; when the map's zoom asks for
// another step, the hidden buffer's tiles are re-pointed at it (setTiles) while its layers stay at opacity 0,
// and once every tile of it is loaded the two swap opacities in one frame. So there is never a frame without
// contours, and each step is drawn whole (no tile of one step beside a tile of another).
//
// A load is never interrupted: a long gesture shows the steps it can keep up with, each one complete. The
// hidden buffer gets a new step only when it is idle, because MapLibre finishes a tile that is loading when
// its URL changes with the old URL's data.
//
// Every step loads the view's tiles again (MapLibre parses and lays out each one), and that work takes the
// cores the map's own drawing needs: on a slow machine back-to-back steps halve the frame rate. So a new step
// starts loading only while the loads of the last LOAD_WINDOW_MS took at most `loadShare` of it: a gesture
// from rest gets its first steps back to back (a short wheel or pinch morphs through them), a long one is
// paced to that share. On a fast machine (loads of a few ms) nothing ever waits; on a slow one the morph shows
// fewer, still whole, steps and the map keeps its frame rate.

import {stepIndex} from './tinterp.js';

/** The window over which loads may take at most `loadShare` of the time. */
export const LOAD_WINDOW_MS = 3000;

const OPACITY = {
  line: ['line-opacity'],
  fill: ['fill-opacity'],
  circle: ['circle-opacity'],
  symbol: ['text-opacity', 'icon-opacity'],
  'fill-extrusion': ['fill-extrusion-opacity'],
  heatmap: ['heatmap-opacity'],
};

export class MorphLayer {
  /**
   * @param {import('./index.js').CcsmMorph} morph
   * @param {import('maplibre-gl').Map} map
   * @param {{id?: string, layers: object[], beforeId?: string, onChange?: (state: object) => void,
   *          onError?: (message: string) => void, loadShare?: number, now?: () => number}} options
   *   loadShare: at most this share of the time goes to loading steps (0 < loadShare <= 1; 1: no pause);
   *   now: the clock in ms (tests)
   */
  constructor(
    morph,
    map,
    {id = 'ccsm-morph', layers, beforeId, onChange, onError, loadShare = 1 / 3, now} = {},
  ) {
    if (!Array.isArray(layers) || !layers.length) throw new Error('ccsm-morph: addTo needs `layers`, the style layers to draw');
    if (!(loadShare > 0 && loadShare <= 1)) throw new Error(`ccsm-morph: loadShare must be in (0, 1], got ${loadShare}`);
    this.morph = morph;
    this.map = map;
    this.id = id;
    this.layerSpecs = layers;
    this.beforeId = beforeId;
    this.onChange = onChange ?? (() => {});
    this.onError = onError ?? (() => {});
    this.meta = null;
    this.buffers = [];
    this.active = null;
    this.pending = null;
    this.swaps = 0;
    this.override = null;
    this.removed = false;
    this.loadShare = loadShare;
    this.now = now ?? (() => globalThis.performance.now());
    this.loads = []; // {start, end} of the recent steps' loads, by the clock
    this._wakeTimer = null;
    this._handlers = {
      render: () => this._tick(),
      sourcedata: (e) => {
        if (this.pending && e.sourceId === this.pending.sourceId && e.tile) this.pending.sawTile = true;
      },
      styledata: () => this._restoreAfterStyleChange(),
      error: (e) => {
        if (!e.sourceId || !this.buffers.some((b) => b.sourceId === e.sourceId)) return;
        const message = e.error?.message ?? String(e.error ?? 'tile error');
        if (!/abort/i.test(message)) this.onError(message);
      },
    };
    for (const [name, fn] of Object.entries(this._handlers)) map.on(name, fn);
    this.ready = morph.metadata().then(
      (meta) => {
        if (this.removed) return;
        this.meta = meta;
        this._start();
      },
      (err) => this.onError(err?.message ?? String(err)),
    );
  }

  /** The step index the map's zoom asks for (clamped to the archive's levels). */
  desiredStep() {
    const steps = this.morph.stepsPerZoom;
    const zoom = this.override ?? this.map.getZoom();
    const lo = (this.meta?.minzoom ?? 0) * steps;
    const hi = ((this.meta?.maxzoom ?? 22) + 1) * steps;
    return Math.min(Math.max(stepIndex(zoom, steps), lo), hi);
  }

  /** The zoom drawn on screen now (a multiple of 1 / stepsPerZoom), or null before the first tiles. */
  get shownZoom() {
    return this.active ? this.active.step / this.morph.stepsPerZoom : null;
  }

  /** Ids of the style layers on screen now (for queryRenderedFeatures). */
  get visibleLayerIds() {
    return this.active ? this.active.layerIds.filter((lid) => this.map.getLayer(lid)) : [];
  }

  /** True when the screen shows the step the camera asks for, with all its tiles. */
  get settled() {
    if (!this.active || this.pending) return false;
    return this.active.step === this.desiredStep() && this._loaded(this.active);
  }

  state() {
    return {
      shownZoom: this.shownZoom,
      pendingZoom: this.pending ? this.pending.step / this.morph.stepsPerZoom : null,
      swaps: this.swaps,
      settled: this.settled,
    };
  }

  /** Pin the drawn zoom (tests, figures); null follows the map again. */
  setOverride(zoom) {
    this.override = zoom;
    this.map.triggerRepaint();
  }

  remove() {
    this.removed = true;
    clearTimeout(this._wakeTimer);
    for (const [name, fn] of Object.entries(this._handlers)) this.map.off(name, fn);
    for (const b of this.buffers) this._removeBuffer(b);
    this.buffers = [];
    this.active = null;
    this.pending = null;
  }

  _start() {
    try {
      this.active = this._addBuffer('a', this.desiredStep(), true);
    } catch (err) {
      // "Style is not done loading": try again once it is.
      if (!/not done loading/i.test(err?.message ?? '')) throw err;
      this.map.once('styledata', () => !this.removed && !this.active && this._start());
      return;
    }
    this.onChange(this.state());
    this.map.triggerRepaint();
  }

  _restoreAfterStyleChange() {
    // map.setStyle() drops our sources and layers: put them back as at the start.
    if (this.removed || !this.active || this.map.getSource(this.active.sourceId)) return;
    this.buffers = [];
    this.active = null;
    this.pending = null;
    this._start();
  }

  _addBuffer(name, step, visible) {
    const sourceId = `${this.id}-${name}`;
    const meta = this.meta;
    const source = {type: 'vector', tiles: [this.morph.tileUrl(step)], minzoom: meta.minzoom, maxzoom: meta.maxzoom};
    if (meta.bounds) source.bounds = meta.bounds;
    if (meta.attribution) source.attribution = meta.attribution;
    this.map.addSource(sourceId, source);
    const layerIds = [];
    const opacities = [];
    for (const spec of this.layerSpecs) {
      const layer = {...spec, id: `${spec.id}-${name}`, source: sourceId};
      if (!layer['source-layer']) layer['source-layer'] = 'contours';
      const props = OPACITY[layer.type] ?? [];
      const own = props.map((p) => [p, spec.paint?.[p] ?? 1]);
      layer.paint = {...spec.paint};
      if (!visible) for (const [p] of own) layer.paint[p] = 0;
      this.map.addLayer(layer, this.beforeId);
      layerIds.push(layer.id);
      opacities.push(own);
    }
    const buffer = {name, sourceId, layerIds, opacities, step, sawTile: false, renders: 0};
    this.buffers.push(buffer);
    return buffer;
  }

  _removeBuffer(buffer) {
    for (const lid of buffer.layerIds) if (this.map.getLayer(lid)) this.map.removeLayer(lid);
    if (this.map.getSource(buffer.sourceId)) this.map.removeSource(buffer.sourceId);
  }

  _setVisible(buffer, visible) {
    buffer.layerIds.forEach((lid, i) => {
      for (const [p, value] of buffer.opacities[i]) this.map.setPaintProperty(lid, p, visible ? value : 0);
    });
  }

  _loaded(buffer) {
    try {
      return this.map.isSourceLoaded(buffer.sourceId);
    } catch {
      return false;
    }
  }

  _tick() {
    if (this.removed || !this.active) return;
    const p = this.pending;
    if (p) {
      p.renders += 1;
      // Loaded, and it has seen a tile (or a few frames went by: nothing in view to wait for).
      if (!this._loaded(p) || !(p.sawTile || p.renders > 3)) return;
      this._swap();
    }
    const want = this.desiredStep();
    if (this.active.step === want) return;
    const wait = this._loadWait(this.now());
    if (wait > 0) {
      // The camera may stop meanwhile (no more render events): come back when the pause is over.
      if (this._wakeTimer === null) {
        this._wakeTimer = setTimeout(() => {
          this._wakeTimer = null;
          if (!this.removed) this.map.triggerRepaint();
        }, wait);
      }
      return;
    }
    let hidden = this.buffers.find((b) => b !== this.active);
    if (!hidden) {
      hidden = this._addBuffer('b', want, false);
    } else {
      if (!this._loaded(hidden)) return; // let what it loads land first (see the top of this file)
      hidden.step = want;
      this.map.getSource(hidden.sourceId).setTiles([this.morph.tileUrl(want)]);
    }
    hidden.sawTile = false;
    hidden.renders = 0;
    hidden.loadStartedAt = this.now();
    this.pending = hidden;
    this.onChange(this.state());
  }

  /** Milliseconds until the loads of the last LOAD_WINDOW_MS take at most `loadShare` of it (0: now). */
  _loadWait(now) {
    const from = now - LOAD_WINDOW_MS;
    this.loads = this.loads.filter((l) => l.end > from);
    // The loads follow one another (one step loads at a time), oldest first: as the window's start moves on,
    // it drops their time in that order, so the wait is where it has dropped the excess over the budget.
    const used = this.loads.reduce((sum, l) => sum + l.end - Math.max(l.start, from), 0);
    let excess = used - this.loadShare * LOAD_WINDOW_MS;
    for (const l of this.loads) {
      if (excess <= 0) break;
      const start = Math.max(l.start, from);
      if (excess <= l.end - start) return start + excess - from;
      excess -= l.end - start;
    }
    return 0;
  }

  _swap() {
    const next = this.pending;
    const old = this.active;
    this._setVisible(next, true);
    this._setVisible(old, false);
    this.active = next;
    this.pending = null;
    this.swaps += 1;
    if (Number.isFinite(next.loadStartedAt)) this.loads.push({start: next.loadStartedAt, end: this.now()});
    this.onChange(this.state());
    this.map.triggerRepaint();
  }
}
