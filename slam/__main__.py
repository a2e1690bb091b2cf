"""``python -m slam``: the same entry point as the ``slam`` console script."""

import sys

from slam.cli import main

sys.exit(main())
