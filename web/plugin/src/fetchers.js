// Where morph tiles come from: a URL template ({z}/{x}/{y}) or a PMTiles archive read with HTTP Range
// requests. Both give the uncompressed tile bytes, or an empty array for "no tile here".

import {PMTiles} from 'pmtiles';

/** Fill a {z}/{x}/{y} URL template ({-y} is the TMS row); relative URLs resolve against `base`. */
export function tileUrl(template, z, x, y, base = undefined) {
  const url = template
    .replace('{z}', String(z))
    .replace('{x}', String(x))
    .replace('{y}', String(y))
    .replace('{-y}', String(2 ** z - 1 - y));
  return base ? new URL(url, base).href : url;
}

/** True when the bytes start with the gzip magic number. */
export function isGzip(bytes) {
  return bytes.length >= 2 && bytes[0] === 0x1f && bytes[1] === 0x8b;
}

/** Gunzip bytes that are gzip (a static host may serve .mvt files gzipped without Content-Encoding). */
export async function gunzipIfNeeded(bytes) {
  if (!isGzip(bytes)) return bytes;
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream('gzip'));
  return new Uint8Array(await new Response(stream).arrayBuffer());
}

/**
 * A tile fetcher for a URL template: (z, x, y) => Promise<Uint8Array>. HTTP 204 and 404 are "no tile".
 * @param {string} template
 * @param {{fetch?: typeof fetch, base?: string}} options
 */
export function templateFetcher(template, {fetch: fetchFn = globalThis.fetch.bind(globalThis), base} = {}) {
  return async (z, x, y) => {
    const url = tileUrl(template, z, x, y, base);
    const response = await fetchFn(url);
    if (response.status === 204 || response.status === 404) return new Uint8Array(0);
    if (!response.ok) throw new Error(`morph tile ${z}/${x}/${y}: HTTP ${response.status} from ${url}`);
    return gunzipIfNeeded(new Uint8Array(await response.arrayBuffer()));
  };
}

/**
 * A tile fetcher for a PMTiles archive (its URL, without the pmtiles:// prefix), and its metadata.
 * The pmtiles package reads the header, directories and tiles with Range requests and decompresses them.
 * @param {string} archiveUrl
 */
export function pmtilesFetcher(archiveUrl) {
  const archive = new PMTiles(archiveUrl);
  const fetchTile = async (z, x, y) => {
    const response = await archive.getZxy(z, x, y);
    if (!response?.data) return new Uint8Array(0);
    return gunzipIfNeeded(new Uint8Array(response.data));
  };
  const metadata = async () => {
    const header = await archive.getHeader();
    const meta = (await archive.getMetadata().catch(() => null)) ?? {};
    return {
      minzoom: header.minZoom,
      maxzoom: header.maxZoom,
      bounds: [header.minLon, header.minLat, header.maxLon, header.maxLat],
      attribution: meta.attribution,
      ccsm_morph: meta.ccsm_morph,
    };
  };
  return {fetchTile, metadata};
}
