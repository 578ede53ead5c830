// Small fetch helpers that turn service errors into readable messages (never swallowed).

/** An HTTP or network failure with a message fit for the status bar. */
export class ServiceError extends Error {
  constructor(message, status = 0, body = null) {
    super(message);
    this.name = 'ServiceError';
    this.status = status;
    this.body = body;
  }
}

/** FastAPI's `detail` is a string, or a list of {loc, msg} for validation errors (422). */
export function formatDetail(detail) {
  if (detail == null) return '';
  if (typeof detail === 'string') return detail;
  if (Array.isArray(detail)) {
    return detail
      .map((d) => {
        if (d && typeof d === 'object') {
          const loc = Array.isArray(d.loc) ? d.loc.filter((p) => p !== 'body').join('.') : '';
          return loc ? `${loc}: ${d.msg}` : String(d.msg ?? JSON.stringify(d));
        }
        return String(d);
      })
      .join('; ');
  }
  if (typeof detail === 'object') return detail.message ?? detail.msg ?? JSON.stringify(detail);
  return String(detail);
}

async function errorFromResponse(response, what) {
  let body;
  let text = '';
  try {
    text = await response.text();
    body = text ? JSON.parse(text) : null;
  } catch {
    body = null;
  }
  const detail = body && typeof body === 'object' && 'detail' in body ? formatDetail(body.detail) : text.slice(0, 200);
  const reason = detail || response.statusText || 'no details';
  return new ServiceError(`${what} failed (HTTP ${response.status}): ${reason}`, response.status, body);
}

/** fetch() that raises ServiceError on a network error or a non-2xx answer. */
export async function request(url, options = {}, what = `${options.method ?? 'GET'} ${url}`) {
  let response;
  try {
    response = await fetch(url, options);
  } catch (err) {
    if (err?.name === 'AbortError') throw err;
    throw new ServiceError(`${what} failed: the tile service is unreachable (${err?.message ?? err})`);
  }
  if (!response.ok) throw await errorFromResponse(response, what);
  return response;
}

export async function getJSON(url, what) {
  const response = await request(url, {headers: {Accept: 'application/json'}}, what);
  return response.json();
}
