"""Detection: streamed video frames, ONNX detectors, multi-object tracking, monocular ranging."""
