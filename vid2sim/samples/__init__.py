"""Sample and test-data generators: synthetic drives, the demo sample, composite clips."""
