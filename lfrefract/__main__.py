"""``python -m lfrefract`` and the ``lfrefract`` script: the core's command line (:mod:`lfrefract.cli`)."""

import sys

from lfrefract._entry import run_command


def main() -> int:
    """Run ``lfrefract`` on ``sys.argv``; returns the exit status."""
    return run_command("lfrefract", "lfrefract.cli")


if __name__ == "__main__":
    sys.exit(main())
