"""`python -m sumo_drvpw.cli ...` = `sumo-drvpw ...`."""

import sys

from sumo_drvpw.cli import main

sys.exit(main())
