// Pure helpers for the morph inside one zoom level (docs/morph-tiles.md, "Drawing at zoom z + f"):
// t at a fraction f of the level from the t samples, the vertex weight w, the fade-in of a contour that
// appears inside the level, and the quantisation of the map zoom to steps.

/**
 * The t samples of one feature: [t, t1, ..., tN] from its properties (N = 8 in format version 1).
 * Samples are read while `t1`, `t2`, ... are numbers, so a tile with fewer samples still works. Returns null
 * when the feature has no numeric `t`.
 * @param {Record<string, unknown>} props
 * @returns {number[] | null}
 */
export function tSamples(props) {
  const t0 = props?.t;
  if (typeof t0 !== 'number' || !Number.isFinite(t0)) return null;
  const out = [t0];
  for (let k = 1; ; k++) {
    const v = props[`t${k}`];
    if (typeof v !== 'number' || !Number.isFinite(v)) break;
    out.push(v);
  }
  return out;
}

/**
 * t at the fraction f (0 <= f <= 1) of the level, piecewise linear between samples evenly spread over the
 * level: samples[k] is t at f = k / N. f outside [0, 1] is clamped. A single sample is a constant.
 * @param {ArrayLike<number>} samples
 * @param {number} f
 */
export function tAt(samples, f) {
  const n = samples.length - 1;
  if (n <= 0) return samples[0];
  const s = Math.min(Math.max(f, 0), 1) * n;
  const k = Math.min(Math.floor(s), n - 1);
  return samples[k] + (s - k) * (samples[k + 1] - samples[k]);
}

/**
 * The weight w of the end geometry at fraction f: P = P_start + w (P_end - P_start), with
 * w = (t(f) - T0) / (TN - T0), and 0 when the contour does not change over the level (TN = T0).
 * @param {ArrayLike<number>} samples
 * @param {number} f
 */
export function morphWeight(samples, f) {
  const t0 = samples[0];
  const tn = samples[samples.length - 1];
  if (tn === t0) return 0;
  return (tAt(samples, f) - t0) / (tn - t0);
}

/**
 * How much of a contour with `min_zoom` is shown at `zoom`: 0 (not drawn) while zoom <= minZoom, then a ramp
 * from 0 to 1 over `fadeSpan` zoom levels, 1 after. fadeSpan <= 0 means no ramp (1 as soon as zoom > minZoom).
 * A contour without min_zoom (null/undefined) is always 1.
 * @param {number | null | undefined} minZoom
 * @param {number} zoom
 * @param {number} fadeSpan
 */
export function fadeAt(minZoom, zoom, fadeSpan) {
  if (minZoom === null || minZoom === undefined) return 1;
  if (!(zoom > minZoom)) return 0;
  if (!(fadeSpan > 0)) return 1;
  return Math.min(1, (zoom - minZoom) / fadeSpan);
}

/**
 * The step index of a map zoom: floor(zoom * steps), tolerant of float noise just below a step.
 * @param {number} zoom
 * @param {number} steps  steps per zoom level
 */
export function stepIndex(zoom, steps) {
  return Math.floor(zoom * steps + 1e-6);
}

/**
 * The fraction of the level of tile zoom z drawn at step zoom `zoom`, clamped to [0, 1]: a tile of a lower
 * zoom than the map's (an over-zoomed or fallback tile) is drawn at its level's end, one of a higher zoom at
 * its start.
 * @param {number} zoom
 * @param {number} z
 */
export function levelFraction(zoom, z) {
  return Math.min(Math.max(zoom - z, 0), 1);
}
