// Choosing among the service's datasets (GET /datasets entries), with no DOM, so node can test it.

/** Where a dataset's TileJSON is: the link the service gave, else the documented route. */
export function tilejsonUrl(ds) {
  return ds.tilejson ?? ds.tilejson_url ?? ds.links?.tilejson ?? `/tiles/${encodeURIComponent(ds.id)}/tilejson.json`;
}

/** The dataset menu's text for one entry. */
export function datasetLabel(ds) {
  let label = ds.name ?? ds.id;
  if (ds.state === 'building') label += ' (building…)';
  if (ds.state === 'failed') label += ' (failed)';
  return label;
}

/** The dataset to show first: the one the URL asks for if it is ready, else the first ready one. */
export function initialDataset(list, wantedId) {
  return list.find((d) => d.id === wantedId && d.state === 'ready') ?? list.find((d) => d.state === 'ready');
}
