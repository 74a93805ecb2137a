"""Mitsuba/Dr.Jit set-up: libLLVM discovery, variant choice, plugin registration.

Import Mitsuba only through :func:`load_mitsuba`. Dr.Jit's LLVM backend needs a libLLVM newer
than many distributions ship; the PyPI package ``karellen-llvm-core`` provides one, which is
found here automatically before Mitsuba is imported. A user-set ``DRJIT_LIBLLVM_PATH`` wins.
"""

from __future__ import annotations

import importlib.metadata
import os
import re
from pathlib import Path
from types import ModuleType

__all__ = ["VARIANTS", "find_libllvm", "load_mitsuba", "versions"]

#: Variants this project renders with, in order of preference.
VARIANTS = ("cuda_ad_rgb", "llvm_ad_rgb")

_LIBLLVM_NAME = re.compile(r"libLLVM(-\d+)?\.so(\.\d+)*$")
_registered: set[str] = set()


def find_libllvm() -> Path | None:
    """Path of the libLLVM shipped by ``karellen-llvm-core``, or None if it is not installed."""
    try:
        files = importlib.metadata.files("karellen-llvm-core") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    candidates = [Path(str(f.locate())).resolve() for f in files if _LIBLLVM_NAME.search(f.name)]
    existing = sorted({p for p in candidates if p.is_file()}, key=lambda p: (len(p.name), p.name))
    return existing[0] if existing else None


def _cuda_available(dr: ModuleType) -> bool:
    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except (AttributeError, RuntimeError):
        return False


def load_mitsuba(variant: str | None = None) -> ModuleType:
    """Import Mitsuba, select a variant and register this project's plugins.

    Parameters
    ----------
    variant : {"cuda_ad_rgb", "llvm_ad_rgb"}, optional
        Default: ``cuda_ad_rgb`` when a CUDA GPU is present, else ``llvm_ad_rgb``.

    Returns
    -------
    module
        The ``mitsuba`` module with the variant set.
    """
    if variant is not None and variant not in VARIANTS:
        raise ValueError(f"variant must be one of {list(VARIANTS)}, got {variant!r}")
    if "DRJIT_LIBLLVM_PATH" not in os.environ:
        lib = find_libllvm()
        if lib is not None:
            os.environ["DRJIT_LIBLLVM_PATH"] = str(lib)
    import drjit as dr
    import mitsuba as mi

    if variant is None:
        variant = "cuda_ad_rgb" if _cuda_available(dr) else "llvm_ad_rgb"
    if mi.variant() != variant:
        mi.set_variant(variant)
    if variant not in _registered:
        from simulator import interface, sensor

        sensor.register(mi)
        interface.register(mi)
        _registered.add(variant)
    return mi


def versions() -> dict[str, str]:
    """Versions of the rendering stack, for sidecars."""
    import drjit as dr
    import mitsuba as mi

    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "variant": str(mi.variant())}
