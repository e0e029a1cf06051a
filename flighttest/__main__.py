import sys

from flighttest.cli import main

sys.exit(main())
