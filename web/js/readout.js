// Texts of the readout bar and the hover tooltip, from plain values (no DOM), so node can test them.

/** t with three decimals. */
export function fmtT(t) {
  return Number(t).toFixed(3);
}

/** "zoom 10.53 · morph 10.500"; the morph part only once a buffer is on screen (q not null). */
export function zoomReadout(zoom, q) {
  return `zoom ${zoom.toFixed(2)}` + (q != null ? ` · morph ${q.toFixed(3)}` : '');
}

/** The t readout: a pinned t, the original (t = 0), or the median (and range) of the t seen on screen. */
export function tReadout(pinnedT, method, stats) {
  let t = 't –';
  if (pinnedT != null) t = `t = ${fmtT(pinnedT)} (pinned)`;
  else if (method === 'original') t = 't = 0 (original)';
  else if (stats) {
    t = `t ≈ ${fmtT(stats.median)}`;
    if (stats.max - stats.min > 0.0005) t += ` (${fmtT(stats.min)}–${fmtT(stats.max)})`;
  }
  return t;
}

/** "120 m (index) · t = 0.250 · CCSM" from a contour feature's properties and the name of its method. */
export function tooltipText(properties, methodName) {
  const p = properties ?? {};
  const elev = Number(p.elevation);
  const elevText = Number.isFinite(elev) ? `${Number.isInteger(elev) ? elev : elev.toFixed(1)} m` : '? m';
  const tVal = Number(p.t);
  const tText = Number.isFinite(tVal) ? `t = ${fmtT(tVal)}` : 't –';
  return `${elevText}${p.index ? ' (index)' : ''} · ${tText} · ${methodName}`;
}
