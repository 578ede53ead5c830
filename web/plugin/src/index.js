// ccsm-morph: continuously morphing ccsm contours in any MapLibre GL JS map.
//
// A CcsmMorph reads morph tiles (docs/morph-tiles.md) from a tile server or a PMTiles archive, fetches each
// tile once, keeps it decoded in a worker (morph-worker.js; in the page where there is none), and serves MapLibre, through a protocol of its own, the layer `contours` as
// drawn at any step of the zoom (stepsPerZoom steps per level), encoded as a vector tile in memory.
// addTo(map, {layers}) draws it with the caller's style layers, double-buffered (layer.js).
//
// No state lives at module level: everything belongs to a CcsmMorph instance.

import {PromiseCache} from './cache.js';
import {pmtilesFetcher, templateFetcher} from './fetchers.js';
import {MorphLayer} from './layer.js';
import {createRenderer} from './morph-worker.js';

export {MorphLayer} from './layer.js';
export {decodeMorphTile, interpolateFeatures, renderMorphTile} from './morphtile.js';
export {encodeMvt} from './mvt.js';
export {fadeAt, morphWeight, tAt, tSamples} from './tinterp.js';

const DEFAULTS = {
  stepsPerZoom: 32,
  fadeSpan: 1 / 8,
  cacheSize: 192,
  scale: 2,
  keepSamples: false,
  worker: true,
};

function randomSuffix() {
  return Math.random().toString(36).slice(2, 8);
}

export class CcsmMorph {
  /**
   * @param {object} options
   * @param {string} [options.url]  a TileJSON URL (the service's /morph/{dataset}/tilejson.json), or
   *   `pmtiles://` followed by the URL of a .pmtiles archive (absolute, or relative to the page)
   * @param {object} [options.tilejson]  instead of url: the morph TileJSON itself
   * @param {string[]} [options.tiles]  instead of url: tile URL templates with {z}/{x}/{y}
   * @param {number} [options.minzoom]  with `tiles`: the archive's zoom range and bounds
   * @param {number} [options.maxzoom]
   * @param {number[]} [options.bounds]
   * @param {number} [options.stepsPerZoom=32]  morph steps drawn per zoom level
   * @param {number} [options.fadeSpan=0.125]  zoom levels over which a contour that appears inside a level
   *   (min_zoom) fades in, through the feature property `morph_fade` (0 ... 1); 0: none
   * @param {number} [options.cacheSize=192]  decoded morph tiles kept in memory
   * @param {number} [options.scale=2]  output extent per morph-tile unit (2: 8192, MapLibre's own precision)
   * @param {boolean} [options.keepSamples=false]  keep the properties t1 ... t8 in the drawn tiles
   * @param {string} [options.protocol]  the protocol name registered with MapLibre (unique per instance)
   * @param {typeof fetch} [options.fetch]  the fetch to use for tiles and TileJSON
   * @param {boolean} [options.worker=true]  decode and draw tiles in a Web Worker (false: in the page)
   */
  constructor(options = {}) {
    this.options = {...DEFAULTS, ...options};
    this.stepsPerZoom = this.options.stepsPerZoom;
    this.protocol = this.options.protocol ?? `ccsm-morph-${randomSuffix()}`;
    this.fetchCount = 0;
    const fetchFn = this.options.fetch ?? globalThis.fetch?.bind(globalThis);
    const base = globalThis.location?.href;
    const url = this.options.url;
    let fetchTile;
    if (url && url.startsWith('pmtiles://')) {
      const archive = pmtilesFetcher(new URL(url.slice('pmtiles://'.length), base).href);
      fetchTile = archive.fetchTile;
      this._metadata = archive.metadata().then((m) => this._withOverrides(m));
    } else if (this.options.tilejson) {
      const tj = this.options.tilejson;
      if (!tj.tiles?.length) throw new Error('ccsm-morph: the TileJSON lists no tiles');
      fetchTile = templateFetcher(tj.tiles[0], {fetch: fetchFn, base});
      this._metadata = Promise.resolve(this._withOverrides(tj));
    } else if (url) {
      this._metadata = fetchFn(new URL(url, base).href)
        .then((r) => {
          if (!r.ok) throw new Error(`ccsm-morph: TileJSON ${url}: HTTP ${r.status}`);
          return r.json();
        })
        .then((tj) => {
          if (!tj.tiles?.length) throw new Error(`ccsm-morph: TileJSON ${url} lists no tiles`);
          return this._withOverrides(tj);
        });
      const inner = (async () => templateFetcher((await this._metadata).tiles[0], {fetch: fetchFn, base}))();
      fetchTile = async (z, x, y) => (await inner)(z, x, y);
    } else if (this.options.tiles?.length) {
      fetchTile = templateFetcher(this.options.tiles[0], {fetch: fetchFn, base});
      this._metadata = Promise.resolve(this._withOverrides({}));
    } else {
      throw new Error('ccsm-morph: give `url` (TileJSON or pmtiles://...) or `tiles`');
    }
    this._metadata.catch(() => {});
    this._renderer = createRenderer({capacity: this.options.cacheSize, useWorker: this.options.worker});
    // Each entry: the tile is fetched and handed to the renderer, which keeps it decoded; {empty}.
    this._tiles = new PromiseCache(this.options.cacheSize, async (key) => {
      const [z, x, y] = key.split('/').map(Number);
      this.fetchCount += 1;
      const bytes = await fetchTile(z, x, y);
      return (await this._renderer).add(key, bytes);
    });
    this._lastStep = null;
    this._direction = 1;
    // A bound function: MapLibre calls it without `this`.
    this.loadTile = (params) => this._loadTile(params);
  }

  _withOverrides(meta) {
    const o = this.options;
    return {
      ...meta,
      minzoom: o.minzoom ?? meta.minzoom ?? 0,
      maxzoom: o.maxzoom ?? meta.maxzoom ?? 22,
      bounds: o.bounds ?? meta.bounds,
      attribution: o.attribution ?? meta.attribution,
    };
  }

  /** {minzoom, maxzoom, bounds, attribution, ...} of the morph tiles. */
  metadata() {
    return this._metadata;
  }

  /** Register the protocol with MapLibre: `ccsm.setupMaplibre(maplibregl)`. */
  setupMaplibre(maplibregl) {
    maplibregl.addProtocol(this.protocol, this.loadTile);
    return this;
  }

  /** Unregister the protocol (the maps using it should be gone first). */
  teardownMaplibre(maplibregl) {
    maplibregl.removeProtocol(this.protocol);
    return this;
  }

  /** The `tiles` URL of a source that draws step `step` (zoom step / stepsPerZoom). */
  tileUrl(step) {
    return `${this.protocol}://step${step}/{z}/{x}/{y}`;
  }

  /** The decoded morph tile z/x/y: fetched once, then from memory. */
  async morphTile(z, x, y) {
    const key = `${z}/${x}/${y}`;
    const renderer = await this._renderer;
    await this._tiles.get(key);
    const tile = await renderer.get(key);
    if (tile) return tile;
    this._tiles.delete(key); // the renderer let it go first: fetch it again
    await this._tiles.get(key);
    return renderer.get(key);
  }

  /** Where tiles are decoded and drawn: 'worker' or 'local' (the page's thread). */
  async rendererMode() {
    return (await this._renderer).mode;
  }

  async _loadTile(params) {
    const m = /^[^:]+:\/\/step(\d+)\/(\d+)\/(\d+)\/(\d+)/.exec(params.url);
    if (!m) throw new Error(`ccsm-morph: bad tile URL ${params.url}`);
    const [step, z, x, y] = m.slice(1).map(Number);
    if (this._lastStep !== null && step !== this._lastStep) this._direction = step > this._lastStep ? 1 : -1;
    this._lastStep = step;
    const key = `${z}/${x}/${y}`;
    const o = this.options;
    const request = {
      z,
      step,
      stepsPerZoom: this.stepsPerZoom,
      direction: this._direction,
      options: {scale: o.scale, fadeSpan: o.fadeSpan, keepSamples: o.keepSamples},
    };
    const renderer = await this._renderer;
    for (let attempt = 0; attempt < 2; attempt++) {
      if ((await this._tiles.get(key)).empty) return {data: new ArrayBuffer(0)};
      const data = await renderer.render(key, request);
      if (data) return {data};
      this._tiles.delete(key); // the renderer let it go first: fetch it again
    }
    throw new Error(`ccsm-morph: tile ${key} was dropped while drawing it`);
  }

  /**
   * Draw the morphing contours on `map` with the given style layers (specs without `source`; their
   * `source-layer` defaults to `contours`). Returns the MorphLayer (remove() takes it off again).
   */
  addTo(map, options) {
    return new MorphLayer(this, map, options);
  }
}
