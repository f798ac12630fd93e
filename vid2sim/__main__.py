import sys

from vid2sim.cli import main

sys.exit(main())
