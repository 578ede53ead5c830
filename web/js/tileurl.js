// The `ccsm://` tile URLs and the real tile URLs they stand for; no DOM, so node can test them.

/** The `tiles` template MapLibre is given for one registered source. */
export function ccsmTemplate(key) {
  return `ccsm://${key}/{z}/{x}/{y}`;
}

/** Split a `ccsm://<key>/<z>/<x>/<y>` URL as MapLibre asks for it; the numbers stay strings. */
export function parseCcsmUrl(url) {
  const match = /^ccsm:\/\/([^/]+)\/(\d+)\/(\d+)\/(\d+)$/.exec(url);
  if (!match) throw new Error(`bad ccsm tile URL ${url}`);
  const [, key, z, x, y] = match;
  return {key, z, x, y};
}

/**
 * Build the real tile URL from a TileJSON template (it keeps its own query string, if any) and our parameters;
 * a relative template is resolved against baseHref (the page).
 */
export function buildTileUrl(template, z, x, y, params, baseHref) {
  const base = new URL(template.replace('{z}', z).replace('{x}', x).replace('{y}', y), baseHref);
  for (const [name, value] of Object.entries(params)) {
    if (value !== null && value !== undefined) base.searchParams.set(name, String(value));
  }
  return base.href;
}
