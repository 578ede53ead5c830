// The service's style.json (GET /styles/{id}/style.json) taken apart for this page: its hillshade, its
// contour line layers (drawn by the morphing layer, so they keep their fade and index weight) and its label
// layers (drawn from the per-level tiles: label anchors are fixed, so they need no morph). Pure functions.

/** The URL of a dataset's style. */
export function styleUrl(datasetId) {
  return `/styles/${encodeURIComponent(datasetId)}/style.json`;
}

/** The style's hillshade as {sourceId, source, layer}, or null when the dataset has no DEM. */
export function hillshadeOf(style) {
  const layer = style?.layers?.find((l) => l.type === 'raster');
  if (!layer) return null;
  const source = style.sources?.[layer.source];
  if (!source) return null;
  return {sourceId: layer.source, source, layer};
}

/** The contour source id of the style (the vector source the line and label layers read). */
export function contourSourceId(style) {
  const line = style?.layers?.find((l) => l.type === 'line');
  return line?.source ?? null;
}

/**
 * The style's contour line layers without their source, for the morphing layer. A contour that appears
 * inside a zoom level grows in: its width is multiplied by the plugin's `morph_fade` (0 ... 1).
 */
export function contourLineLayers(style) {
  const lines = (style?.layers ?? []).filter((l) => l.type === 'line' && l['source-layer'] === 'contours');
  return lines.map((l) => {
    const rest = {...l};
    delete rest.source;
    return {...rest, paint: {...l.paint, 'line-width': grownIn(l.paint?.['line-width'] ?? 1)}};
  });
}

/**
 * A width times `morph_fade`. A zoom ramp (`interpolate` or `step` on `["zoom"]`) must stay the top of the
 * expression in MapLibre, so there each stop's output is multiplied instead.
 */
function grownIn(width) {
  const fade = (w) => ['*', w, ['coalesce', ['get', 'morph_fade'], 1]];
  const isZoomRamp = Array.isArray(width) && width[0] === 'interpolate' && JSON.stringify(width[2]) === '["zoom"]';
  if (isZoomRamp) return [...width.slice(0, 3), ...width.slice(3).map((v, i) => (i % 2 ? fade(v) : v))];
  const isZoomStep = Array.isArray(width) && width[0] === 'step' && JSON.stringify(width[1]) === '["zoom"]';
  if (isZoomStep) return [...width.slice(0, 2), ...width.slice(2).map((v, i) => (i % 2 ? v : fade(v)))];
  return fade(width);
}

/** The style's label layers, reading from `sourceId`. */
export function labelLayers(style, sourceId) {
  const labels = (style?.layers ?? []).filter((l) => l.type === 'symbol' && l['source-layer'] === 'contour_labels');
  return labels.map((l) => ({...l, source: sourceId}));
}

/** Width of the compared method's lines in the overlay (CSS px): below the style's thinnest line (0.7 px). */
export const COMPARE_LINE_WIDTH = 0.5;

/**
 * The style's contour line layers for the compared method of the overlay: the same ranks, filters and fades,
 * in one contrasting colour and as a hairline drawn over the main method's lines, whose heavier index lines
 * show on both sides of it, and whose other lines show beside it wherever the two methods differ.
 */
export function comparisonLayers(lines, color) {
  return lines.map((l) => ({
    ...l,
    paint: {
      ...l.paint,
      'line-color': color,
      'line-width': ['*', COMPARE_LINE_WIDTH, ['coalesce', ['get', 'morph_fade'], 1]],
    },
  }));
}
