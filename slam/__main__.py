"""``python -m slam``: the same entry point as the ``slam`` console script."""

from slam.cli import entry

entry()
