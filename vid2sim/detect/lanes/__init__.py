"""Lane markings: per-frame measurement, ground-plane geometry, the lane track over a clip, the vanishing point."""
