"""``python -m sitl_fakes``: run the fake PX4 quadcopter (see ``sitl_fakes/README.md``)."""

import os
import sys

os.environ.setdefault("MAVLINK20", "1")

from sitl_fakes.app import main

if __name__ == "__main__":
    sys.exit(main())
