"""``ccsm simplify`` and ``ccsm evaluate`` (owned by the engine CLI work)."""
