"""Vehicles in a frame: ONNX detectors, the windows they look at, importers of other tools' boxes."""
