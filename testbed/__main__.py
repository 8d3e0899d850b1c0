"""``python -m testbed``: the same entry point as the ``testbed`` console script."""

import sys

from testbed.cli.main import main

sys.exit(main())
