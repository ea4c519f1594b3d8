"""GRLAA anti-aliased polylines (seed 001) drawn over frames."""
