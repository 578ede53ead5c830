// Type declarations of ccsm-morph's public API (src/index.js and what it re-exports), written by hand.
// Checked by `npm test` (tsc --noEmit on example/usage.ts, which uses the API as the README does).
// The MapLibre types come from the peer dependency maplibre-gl.

import type {
  AddProtocolAction,
  CircleLayerSpecification,
  FillExtrusionLayerSpecification,
  FillLayerSpecification,
  HeatmapLayerSpecification,
  LineLayerSpecification,
  Map as MaplibreMap,
  RequestParameters,
  SymbolLayerSpecification,
} from 'maplibre-gl';

/** [west, south, east, north] in degrees. */
export type Bounds = [number, number, number, number];

/** A morph TileJSON, as the service's `/morph/{dataset}/tilejson.json` gives it (only `tiles` is required). */
export interface MorphTileJSON {
  tiles: string[];
  minzoom?: number;
  maxzoom?: number;
  bounds?: Bounds;
  attribution?: string;
  [key: string]: unknown;
}

/** Where the morph tiles come from: exactly one of `url`, `tilejson` or `tiles`. */
export type MorphSourceOptions =
  | {
      /** A morph TileJSON URL, or `pmtiles://` + the archive's URL (absolute or relative to the page). */
      url: string;
      tilejson?: never;
      tiles?: never;
    }
  | {
      /** The morph TileJSON itself. */
      tilejson: MorphTileJSON;
      url?: never;
      tiles?: never;
    }
  | {
      /** Tile URL templates with `{z}`, `{x}`, `{y}` (or `{-y}`); the first one is used. */
      tiles: string[];
      url?: never;
      tilejson?: never;
    };

/** Options of `new CcsmMorph(…)` besides the source of the tiles. */
export interface CcsmMorphSettings {
  /** Zoom range and bounds; override what the TileJSON or the archive's header says. */
  minzoom?: number;
  maxzoom?: number;
  bounds?: Bounds;
  attribution?: string;
  /** Steps drawn per zoom level (default 32: the zoom is quantised to 1/32). */
  stepsPerZoom?: number;
  /** Zoom levels over which `morph_fade` goes from 0 to 1 after a contour's `min_zoom` (default 1/8; 0: none). */
  fadeSpan?: number;
  /** Decoded morph tiles kept in memory, least recently used go first (default 192). */
  cacheSize?: number;
  /** Output extent per morph-tile unit (default 2: 8192, MapLibre's own precision). */
  scale?: number;
  /** Keep `t1` … `t8` in the drawn features (default false). */
  keepSamples?: boolean;
  /** The protocol name registered with MapLibre (default: random, unique per instance). */
  protocol?: string;
  /** The fetch used for the TileJSON and the tiles (default: the global fetch). */
  fetch?: typeof fetch;
  /** Decode and draw tiles in a module worker (default true; false, or no Worker: in the page's thread). */
  worker?: boolean;
}

export type CcsmMorphOptions = MorphSourceOptions & CcsmMorphSettings;

/** What `metadata()` resolves to: the TileJSON's fields (or the archive header's) with the overrides applied. */
export interface MorphMetadata {
  minzoom: number;
  maxzoom: number;
  bounds?: Bounds;
  attribution?: string;
  tiles?: string[];
  /** The archive's `ccsm_morph` metadata (format version, samples per level), when it has one. */
  ccsm_morph?: unknown;
  [key: string]: unknown;
}

/** The properties of one contour the plugin draws in layer `contours` (for `['get', …]` and queryRenderedFeatures). */
export interface ContourProperties {
  /** Height of the contour, in the dataset's unit. */
  elevation: number;
  /** True on index contours (every 5th interval). */
  index: boolean;
  /** t at the drawn zoom, interpolated between the samples (0 = source detail, 1 = the target). */
  t?: number;
  /** 0 … 1: how far a contour that appears inside the level (min_zoom) has grown in; 1 everywhere else. */
  morph_fade: number;
  /** Only on a contour that appears inside the level: it is drawn only where zoom > min_zoom. */
  min_zoom?: number;
  /** The interval schedule of the morph tile (docs/morph-tiles.md), passed through as they are. */
  level?: number;
  rank?: number;
  fade_zoom?: number;
  hide_zoom?: number;
  /** `t1` … `t8` with `keepSamples`, and any other property the morph tile carries. */
  [key: string]: string | number | boolean | undefined;
}

type WithoutSource<L> = L extends unknown ? Omit<L, 'source' | 'source-layer'> & {'source-layer'?: string} : never;

/**
 * A style layer the plugin draws its contours with: an ordinary MapLibre layer of a type that draws vector
 * tiles, without `source`; `source-layer` defaults to `contours`.
 */
export type MorphStyleLayer = WithoutSource<
  | LineLayerSpecification
  | FillLayerSpecification
  | CircleLayerSpecification
  | SymbolLayerSpecification
  | FillExtrusionLayerSpecification
  | HeatmapLayerSpecification
>;

/** `MorphLayer.state()`, also passed to `onChange`. */
export interface MorphLayerState {
  /** The zoom drawn on screen (a multiple of 1 / stepsPerZoom), or null before the first tiles. */
  shownZoom: number | null;
  /** The step being loaded into the hidden buffer, or null. */
  pendingZoom: number | null;
  /** Buffer swaps so far. */
  swaps: number;
  settled: boolean;
}

export interface AddToOptions {
  /** Prefix of the two sources (`{id}-a`, `{id}-b`); default 'ccsm-morph'. */
  id?: string;
  /** The style layers to draw (at least one). */
  layers: MorphStyleLayer[];
  /** Draw below this layer of the map's style. */
  beforeId?: string;
  onChange?: (state: MorphLayerState) => void;
  onError?: (message: string) => void;
  /**
   * At most this share of the time goes to loading morph steps (0 < loadShare <= 1, default 1/3): a step starts
   * loading only while the loads of the last 3 s took at most this share of them. 1: no pause.
   */
  loadShare?: number;
  /** The clock in ms (default `performance.now`); for tests. */
  now?: () => number;
}

/** The part of the maplibre-gl module `setupMaplibre` needs (`import * as maplibregl from 'maplibre-gl'`). */
export interface MaplibreProtocols {
  addProtocol(customProtocol: string, loadFn: AddProtocolAction): void;
}

/** The part of the maplibre-gl module `teardownMaplibre` needs. */
export interface MaplibreProtocolRemoval {
  removeProtocol(customProtocol: string): void;
}

/** A flattened geometry: x, y pairs and the start offset (into `xy`) of each part, plus the end. */
export interface FlatGeometry {
  xy: Float64Array;
  offsets: Uint32Array;
}

export interface DecodedMorphFeature {
  id: number | undefined;
  properties: Record<string, string | number | boolean>;
  /** [t, t1, …, t8], or null when the feature has no numeric t. */
  samples: number[] | null;
  minZoom: number | null;
  start: FlatGeometry;
  /** The geometry at the level's end, or null when the feature does not move. */
  end: FlatGeometry | null;
}

/** A morph tile decoded once (`decodeMorphTile`). */
export interface DecodedMorphTile {
  extent: number;
  features: DecodedMorphFeature[];
  /** Features whose `contours_end` geometry was missing or of another shape (drawn unmoved). */
  mismatched: number;
}

/** One feature for `encodeMvt`; each part is a flat [x0, y0, x1, y1, …] in tile units. */
export interface MvtFeature {
  id?: number;
  /** 1 POINT, 2 LINESTRING (default), 3 POLYGON. */
  type?: 1 | 2 | 3;
  parts: ArrayLike<ArrayLike<number>>;
  properties?: Record<string, string | number | boolean | null | undefined>;
}

export interface MvtLayer {
  name: string;
  extent?: number;
  features: MvtFeature[];
}

export interface InterpolateOptions {
  /** Output units per tile unit (default 1). */
  scale?: number;
  /** Zoom levels over which a contour fades in after its min_zoom (default 0: at once). */
  fadeSpan?: number;
  /** Keep t1 … tN (default false). */
  keepSamples?: boolean;
}

export interface RenderOptions extends InterpolateOptions {
  /** The output layer's name (default 'contours'). */
  layerName?: string;
}

/** One set of morph tiles; share it between maps (each tile is fetched once for all). */
export class CcsmMorph {
  constructor(options: CcsmMorphOptions);
  readonly options: CcsmMorphOptions & Required<Pick<CcsmMorphSettings, 'stepsPerZoom' | 'fadeSpan' | 'cacheSize' | 'scale' | 'keepSamples'>>;
  readonly stepsPerZoom: number;
  /** The protocol name registered with MapLibre. */
  readonly protocol: string;
  /** Morph tiles fetched so far. */
  readonly fetchCount: number;
  /** The protocol's load function (bound: MapLibre calls it without `this`). */
  readonly loadTile: (params: RequestParameters) => Promise<{data: ArrayBuffer}>;
  metadata(): Promise<MorphMetadata>;
  /** Register the protocol with MapLibre; returns this. */
  setupMaplibre(maplibregl: MaplibreProtocols): this;
  /** Unregister the protocol (the maps using it should be gone first); returns this. */
  teardownMaplibre(maplibregl: MaplibreProtocolRemoval): this;
  /** The `tiles` URL of a source that draws step `step` (zoom = step / stepsPerZoom). */
  tileUrl(step: number): string;
  /** The decoded morph tile z/x/y: fetched once, then from memory. */
  morphTile(z: number, x: number, y: number): Promise<DecodedMorphTile>;
  /** Where tiles are decoded and drawn: 'worker' (a module worker) or 'local' (the page's thread). */
  rendererMode(): Promise<'worker' | 'local'>;
  /** Draw the morphing contours on `map` with the given style layers; may be called before the style loads. */
  addTo(map: MaplibreMap, options: AddToOptions): MorphLayer;
}

/** One map's morphing contours (what `addTo` returns). */
export class MorphLayer {
  constructor(morph: CcsmMorph, map: MaplibreMap, options: AddToOptions);
  readonly morph: CcsmMorph;
  readonly map: MaplibreMap;
  readonly id: string;
  /** Resolves once the metadata is in and the sources are added (or the error went to onError). */
  readonly ready: Promise<void>;
  readonly swaps: number;
  /** The pinned zoom, or null when the drawn zoom follows the map. */
  readonly override: number | null;
  /** The zoom drawn on screen now (a multiple of 1 / stepsPerZoom), or null before the first tiles. */
  readonly shownZoom: number | null;
  /** Ids of the style layers on screen now (for queryRenderedFeatures). */
  readonly visibleLayerIds: string[];
  /** True when the screen shows the step the camera asks for, with all its tiles. */
  readonly settled: boolean;
  /** The step index the map's zoom asks for (clamped to the archive's levels). */
  desiredStep(): number;
  state(): MorphLayerState;
  /** Pin the drawn zoom (tests, figures); null follows the map again. */
  setOverride(zoom: number | null): void;
  remove(): void;
}

/** The t samples [t, t1, …, tN] of a feature's properties, or null without a numeric `t`. */
export function tSamples(props: Record<string, unknown> | null | undefined): number[] | null;
/** t at the fraction f (0 … 1, clamped) of the level, piecewise linear between the samples. */
export function tAt(samples: ArrayLike<number>, f: number): number;
/** The weight of the end geometry at fraction f: (t(f) - T0) / (TN - T0), 0 when TN = T0. */
export function morphWeight(samples: ArrayLike<number>, f: number): number;
/** How much of a contour with `minZoom` is shown at `zoom` (0 … 1), ramping over `fadeSpan` zoom levels. */
export function fadeAt(minZoom: number | null | undefined, zoom: number, fadeSpan: number): number;
/** Decode a morph tile (uncompressed MVT bytes); empty input gives an empty tile. */
export function decodeMorphTile(bytes: ArrayBuffer | Uint8Array | null | undefined): DecodedMorphTile;
/** The features of layer `contours` drawn at map zoom `zoom` from a decoded morph tile of zoom `z`. */
export function interpolateFeatures(
  tile: DecodedMorphTile,
  z: number,
  zoom: number,
  options?: InterpolateOptions,
): Array<Required<Pick<MvtFeature, 'type'>> & {id: number | undefined; parts: Float64Array[]; properties: ContourProperties}>;
/** One vector tile with layer `contours` as drawn at `zoom`, at extent tile.extent * scale. */
export function renderMorphTile(tile: DecodedMorphTile, z: number, zoom: number, options?: RenderOptions): Uint8Array;
/** Encode layers as one Mapbox Vector Tile. */
export function encodeMvt(layers: MvtLayer[]): Uint8Array;
