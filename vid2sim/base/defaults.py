"""Project-wide defaults and conventions, each stated once with its reason and source.

Stage-specific tuning lives in each stage's config class (``TrackerConfig``,
``RangingConfig``, ``TraceParams``, ``AssembleConfig``, ...); this module holds only the
numbers several stages must agree on.
"""

from __future__ import annotations

#: Width of a lane where nothing better is known [m]: 3.5 m is the standard lane of German
#: and EU main roads (RASt 06 / RAA 2008 give 3.25-3.75 m), 3.6 m (12 ft) the US
#: interstate lane (FHWA); urban lanes run narrower (3.0-3.25 m). Used for the ego corridor of
#: lead selection, trajectory-only roads and the report's lead test alike.
LANE_WIDTH_M = 3.5

#: Ego vehicle dimensions where nothing better is known [m]: a mid-size passenger car
#: (VW Golf VIII: 4.28 x 1.79 x 1.46 m; VW Passat B8: 4.77 x 1.83 x 1.46 m), the class that
#: records most dash-cam footage.
EGO_LENGTH_M, EGO_WIDTH_M, EGO_HEIGHT_M = 4.5, 1.8, 1.5

#: Frame rate assumed for a folder of images when none is given [frames/s]: KITTI's cameras
#: are triggered at 10 Hz by the lidar (Geiger et al., IJRR 2013), the folder format users
#: meet most; the label files count frames at that rate too.
IMAGE_FOLDER_FPS = 10.0

#: Sample rate of the ego trajectory [Hz]: the rate of the scenario's trajectories and of
#: the gym environment's policy steps (highway-env's default policy frequency is 1-5 Hz;
#: 10 Hz resolves a 0.5 s TTC step and matches KITTI's frames).
EGO_RATE_HZ = 10.0

#: Median absolute deviation -> one-sigma of a Gaussian: 1 / Phi^-1(3/4) = 1.4826.
MAD_TO_SIGMA = 1.4826
