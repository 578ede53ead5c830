// Upload a GeoJSON contour set (file input or drag-and-drop) and follow its build.

import {getJSON, request, ServiceError, formatDetail} from './api.js';

const POLL_MS = 500;

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

/** 0..1 from whatever the service reports (a fraction, a percentage, or done/total counts). */
export function progressFraction(ds) {
  const p = ds?.build ?? ds?.progress;
  if (typeof p === 'number') return p > 1 ? p / 100 : p;
  if (p && typeof p === 'object') {
    if (typeof p.fraction === 'number') return p.fraction;
    const done = p.done ?? p.built ?? p.completed;
    const total = p.total ?? p.count;
    if (typeof done === 'number' && typeof total === 'number' && total > 0) return done / total;
  }
  return ds?.state === 'ready' ? 1 : null;
}

function failureMessage(ds, fileName) {
  const why = formatDetail(ds.build?.error ?? ds.error ?? ds.detail ?? ds.message) || 'no reason given';
  return `Building “${ds.name ?? fileName}” failed: ${why}`;
}

/**
 * POST the file, then poll until the dataset is ready. Calls onProgress(dataset, fraction|null) on every poll.
 * scales: optional {source_scale, target_scale} denominators as typed (strings; empty means the default).
 * Resolves with the ready dataset; rejects with a ServiceError whose message can be shown as it is.
 */
export async function uploadDataset(file, {onProgress = () => {}, scales = {}} = {}) {
  // The service takes the GeoJSON document itself as the body (docs/service.md, POST /datasets).
  const name = file.name.replace(/\.(geo)?json$/i, '');
  const query = new URLSearchParams({name});
  // Scales left empty are the service's defaults; a bad one comes back as the service's 422 message.
  for (const [key, value] of Object.entries(scales)) if (value) query.set(key, value);
  const url = `/datasets?${query}`;
  const response = await request(
    url,
    {method: 'POST', body: file, headers: {'Content-Type': 'application/geo+json'}},
    `Upload of “${file.name}”`,
  );
  let ds = await response.json();
  if (!ds?.id) throw new ServiceError(`Upload of “${file.name}”: the service answered without a dataset id`);
  onProgress(ds, progressFraction(ds));
  while (ds.state !== 'ready') {
    if (ds.state === 'failed') throw new ServiceError(failureMessage(ds, file.name), 0, ds);
    await sleep(POLL_MS);
    ds = await getJSON(`/datasets/${encodeURIComponent(ds.id)}`, `Progress of “${file.name}”`);
    onProgress(ds, progressFraction(ds));
  }
  return ds;
}

/** Whole-page drag-and-drop; calls onFile(file) for the first dropped file. */
export function installDropZone(zoneEl, onFile) {
  let depth = 0;
  const hasFiles = (e) => Array.from(e.dataTransfer?.types ?? []).includes('Files');
  window.addEventListener('dragenter', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    depth += 1;
    zoneEl.hidden = false;
  });
  window.addEventListener('dragover', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    e.dataTransfer.dropEffect = 'copy';
  });
  window.addEventListener('dragleave', (e) => {
    if (!hasFiles(e)) return;
    depth = Math.max(0, depth - 1);
    if (depth === 0) zoneEl.hidden = true;
  });
  window.addEventListener('drop', (e) => {
    if (!hasFiles(e)) return;
    e.preventDefault();
    depth = 0;
    zoneEl.hidden = true;
    const file = e.dataTransfer.files?.[0];
    if (file) onFile(file);
  });
}
