"""``ccsm serve`` and ``ccsm build`` (owned by the tile service work)."""
