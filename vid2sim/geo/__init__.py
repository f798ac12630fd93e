"""Geography: GPS readers, the local ENU frame, the ego trajectory, roads and map matching."""
