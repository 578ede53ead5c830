"""Reading contours and DEMs, coordinate reference systems, writing GeoJSON, the bundled sample."""
