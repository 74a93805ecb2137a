"""The one rule for every seed of the simulator.

A seed is an integer (a Python ``int`` or a numpy integer, never a ``bool``) in
``[0, SEED_LIMIT)``, ``SEED_LIMIT = 2**31``: the render seed (``render.seed``), the seed of a
random texture (``texture_seed``) and of a figurine's shape (``seed``), the sweep seed of a
dataset spec (``sweep.seed``) and the seed arguments of :mod:`simulator.assets`. The bound keeps
every seed inside Mitsuba's 32-bit sampler seed (from which each band's seed is derived,
:func:`simulator.render.band_seed`), inside numpy's generators, and a non-negative int32 for any
reader of the files that record it. The seeds derived from one (a sample's, from the sweep seed:
:func:`simulator.dataset.spec.sample_seed`) are in the same range.

Each seed is checked once, where it enters: when its scene, spec or asset call is parsed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from lfrefract.errors import ParameterError
from lfrefract.validate import shown

__all__ = ["SEED_LIMIT", "seed"]

#: Seeds are integers in [0, SEED_LIMIT).
SEED_LIMIT = 2**31


def seed(name: str, value: Any) -> int:
    """``value`` as a seed: an ``int`` in ``[0, SEED_LIMIT)``.

    Parameters
    ----------
    name : str
        The key in messages (``"render.seed"``).
    value : int or numpy integer

    Raises
    ------
    ParameterError
        For a bool, a non-integer (``3.0`` included) or an integer outside ``[0, 2**31)``; the
        message names ``name`` and the value.
    """
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not 0 <= value < SEED_LIMIT:
        raise ParameterError(f"{name} must be an integer in [0, 2**31), got {shown(value)}")
    return int(value)
