"""`python -m sumo_drvpw ...` = `sumo-drvpw ...`."""

import sys

from sumo_drvpw.cli import main

sys.exit(main())
