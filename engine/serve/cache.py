"""A thread-safe LRU cache bounded by a total cost (entries or bytes)."""

from __future__ import annotations

import threading
from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import Generic, TypeVar

K = TypeVar("K", bound=Hashable)


V = TypeVar("V")


class LRUCache(Generic[K, V]):
    """A thread-safe least-recently-used cache bounded by a total cost (entries or bytes)."""

    def __init__(self, max_cost: int, cost: Callable[[V], int] = lambda v: 1) -> None:
        self.max_cost = max_cost
        self._cost = cost
        self._data: OrderedDict[K, tuple[V, int]] = OrderedDict()
        self._total = 0
        self._lock = threading.Lock()
        self.hits = 0
        self.misses = 0

    def get(self, key: K) -> V | None:
        """The cached value, or None."""
        with self._lock:
            item = self._data.get(key)
            if item is None:
                self.misses += 1
                return None
            self._data.move_to_end(key)
            self.hits += 1
            return item[0]

    def put(self, key: K, value: V) -> None:
        """Store a value, evicting the least recently used ones beyond ``max_cost``."""
        c = self._cost(value)
        with self._lock:
            old = self._data.pop(key, None)
            if old is not None:
                self._total -= old[1]
            self._data[key] = (value, c)
            self._total += c
            while self._total > self.max_cost and len(self._data) > 1:
                _, (_, oc) = self._data.popitem(last=False)
                self._total -= oc

    def clear(self) -> None:
        """Drop everything."""
        with self._lock:
            self._data.clear()
            self._total = 0

    def __len__(self) -> int:
        return len(self._data)

    @property
    def total_cost(self) -> int:
        """Sum of the costs of the cached values."""
        return self._total
