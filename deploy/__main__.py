"""`python -m deploy ...`: the runtime's command line without robot_hoi (same options as `robot-hoi deploy`)."""

import sys

from deploy.cli import main

sys.exit(main())
