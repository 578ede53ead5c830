// A small least-recently-used cache of promises: each key is loaded once, concurrent callers share the load,
// a failed load is forgotten (so it can be tried again), and the oldest entries go past `capacity`.

export class PromiseCache {
  /**
   * @param {number} capacity  entries kept
   * @param {(key: string) => Promise<unknown>} load
   */
  constructor(capacity, load) {
    this.capacity = Math.max(1, capacity);
    this.load = load;
    this.entries = new Map();
    this.loads = 0;
  }

  get(key) {
    let entry = this.entries.get(key);
    if (entry) {
      // Move to the newest end.
      this.entries.delete(key);
      this.entries.set(key, entry);
      return entry;
    }
    this.loads += 1;
    entry = Promise.resolve().then(() => this.load(key));
    this.entries.set(key, entry);
    entry.catch(() => {
      if (this.entries.get(key) === entry) this.entries.delete(key);
    });
    while (this.entries.size > this.capacity) this.entries.delete(this.entries.keys().next().value);
    return entry;
  }

  has(key) {
    return this.entries.has(key);
  }

  /** Forget `key` (its next get loads it again). */
  delete(key) {
    this.entries.delete(key);
  }

  clear() {
    this.entries.clear();
  }
}
