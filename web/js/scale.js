// Zoom <-> map scale, and the fractional "morph zoom" sent to the tile service.
//
// MapLibre draws vector tiles at 512 px; with the OGC pixel of 0.28 mm the scale denominator at zoom z and
// latitude phi is S = 2*pi*6378137*cos(phi) / (512 * 2^z) / 0.00028 = 279,541,132 * cos(phi) / 2^z
// (docs/design.md section 4).

export const SCALE_AT_ZOOM_0 = (2 * Math.PI * 6378137) / 512 / 0.00028; // 279,541,132.01...

/** Morph steps per zoom level: the service gets zoom quantised to 1/STEPS_PER_ZOOM. */
export const STEPS_PER_ZOOM = 8;

/** Scale denominator S (1:S) at a fractional zoom and a latitude in degrees. */
export function scaleDenominator(zoom, latDeg) {
  return (SCALE_AT_ZOOM_0 * Math.cos((latDeg * Math.PI) / 180)) / 2 ** zoom;
}

/** "1:123,000": three significant digits, grouped. */
export function formatScale(denominator) {
  if (!Number.isFinite(denominator) || denominator <= 0) return '1:–';
  const digits = Math.floor(Math.log10(denominator));
  const unit = 10 ** Math.max(0, digits - 2);
  return `1:${(Math.round(denominator / unit) * unit).toLocaleString('en-US')}`;
}

/** Quantise a map zoom down to the step grid: q = floor(zoom * 8) / 8 (tolerant of float noise). */
export function quantiseZoom(zoom, steps = STEPS_PER_ZOOM) {
  return Math.floor(zoom * steps + 1e-6) / steps;
}

/**
 * The zoom= value for one tile request: the source's quantised zoom q, kept inside [z, z + 1) for the tile's
 * integer z. Tiles of another z than floor(q) are only asked for in passing (while the next source loads, or
 * over-zoomed past the source's maxzoom), and the service accepts only zoom in [z, z + 1).
 */
export function morphZoomForTile(q, z, steps = STEPS_PER_ZOOM) {
  return Math.min(Math.max(q, z), z + 1 - 1 / steps);
}

/**
 * The morph zoom a dataset's source is made for: below its minzoom nothing is drawn, and past its maxzoom tiles
 * are over-zoomed so the shape no longer changes; q is kept inside [minzoom, maxzoom + 1).
 */
export function clampMorphZoom(q, minzoom, maxzoom, steps = STEPS_PER_ZOOM) {
  return Math.min(Math.max(q, minzoom), maxzoom + 1 - 1 / steps);
}
