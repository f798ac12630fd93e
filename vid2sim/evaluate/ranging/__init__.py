"""Truth for monocular ranging from real measurements, and its figures.

:mod:`.kitti` reads the truth of KITTI tracking labels (lidar-annotated 3D boxes: rear
distance and its rate); :mod:`.static` derives the range and range rate of static vehicles
from a KITTI raw drive's OXTS ego motion. Tests and benchmarks both import them from here.
"""
