"""SQLite persistence of built datasets (nothing else: no geometry, no reprojection, no builds)."""
