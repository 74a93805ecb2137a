"""``python -m simulator`` and the ``lfsim`` script: the simulator's command line (:mod:`simulator.cli`)."""

import sys

from lfrefract._entry import run_command


def main() -> int:
    """Run ``lfsim`` on ``sys.argv``; returns the exit status."""
    return run_command("lfsim", "simulator.cli")


if __name__ == "__main__":
    sys.exit(main())
