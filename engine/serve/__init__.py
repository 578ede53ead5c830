"""Serving built datasets: packs, one renderer per generalization method, caches, relief, static export."""
