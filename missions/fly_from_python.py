"""Fly a mission from your own script: ``python missions/fly_from_python.py [URL]`` (default: PX4 SITL's port).

The same flight as ``flighttest fly helix --height 7 --descent 5 --vehicle x500 --yes``, through the library.
"""

import sys

from flighttest import fly_mission

url = sys.argv[1] if len(sys.argv) > 1 else "udpin://0.0.0.0:14540"
outcome = fly_mission("helix", connect=url, vehicle="x500", height_m=7.0, descent_m=5.0, yes=True)
print(outcome.outcome, outcome.abort_reason or "", outcome.descent_time_s, outcome.log_dir)
sys.exit(outcome.exit_code)
