"""Evaluation: annotation readers, scenario replay at keyframes, IoU metrics and the report."""
