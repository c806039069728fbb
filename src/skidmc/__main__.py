"""``python -m skidmc``: the ``skidmc`` command."""

import sys

from skidmc.cli import main

sys.exit(main())
