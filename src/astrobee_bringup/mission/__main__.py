"""`python -m astrobee_bringup.mission`: the mission's command line."""
import sys

from .cli import main

sys.exit(main())
