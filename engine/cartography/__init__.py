"""Cartography of a contour set: which interval is drawn at which scale, labels and units (docs/design.md
section 9)."""
