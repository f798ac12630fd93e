"""Export: scenario assembly, the highway-env gymnasium environment, OpenSCENARIO/OpenDRIVE."""
