"""``python -m lfrefract``: the core's command line, as the ``lfrefract`` script."""

import sys

from lfrefract.cli import main

if __name__ == "__main__":
    sys.exit(main())
