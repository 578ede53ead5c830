"""Serving built datasets: records, packs, one renderer per generalization method, caches, dataset builds."""
