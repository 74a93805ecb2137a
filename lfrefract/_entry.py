"""The command lines' entry: Ctrl-C or SIGTERM while a command is still loading ends in one line.

``lfrefract`` and ``lfsim`` import numpy, scipy, OpenCV, numba and the rest before their ``main``
runs and installs its handlers (:func:`lfrefract.formats.outputs.terminate_cleanly`): seconds in
which Ctrl-C would print Python's ``KeyboardInterrupt`` traceback. :func:`run_command` covers that
time. Nothing is written while a command loads, so the process ends at once.
"""

from __future__ import annotations

import importlib
import os
import signal

__all__ = ["run_command"]


def _stop_while_loading(prog: str):
    def handler(signum, frame):
        os.write(2, f"{prog}: interrupted while starting (signal {signum}); nothing was written\n".encode())
        os._exit(128 + signum)

    return handler


def run_command(prog: str, module: str, function: str = "main") -> int:
    """Import ``module`` and return ``module.function()``, ending in one line if interrupted meanwhile.

    Parameters
    ----------
    prog : str
        The command's name, for the message (``"lfsim"``).
    module, function : str
        Where the command line's ``main`` is (``"simulator.cli"``, ``"main"``).

    Returns
    -------
    int
        The command's exit status. SIGINT or SIGTERM during the import ends the process with status
        130 or 143 and one line on standard error; from ``main`` on, its own handlers answer them.
    """
    signals = (signal.SIGINT, signal.SIGTERM)
    previous = {s: signal.signal(s, _stop_while_loading(prog)) for s in signals}
    try:
        main = getattr(importlib.import_module(module), function)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    return main()
