"""Polyline helpers shared by every method: lengths, resampling, Douglas–Peucker, compiled kernels."""
