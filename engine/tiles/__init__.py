"""The tile grid and scale math, row significance for thinning, clipping and MVT encoding."""
