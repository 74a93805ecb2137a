"""Memory estimates and the check that refuses work which cannot fit, before anything is allocated.

Every estimate here is of the peak memory, bytes, that an operation adds to the process (not
counting what its caller already holds), from the arrays it allocates; each is within about a
factor of two of what ``tracemalloc`` measured on the tiny cameras, and errs high.
:func:`require_memory` compares one with the memory the machine has available now.
"""

from __future__ import annotations

import os
from pathlib import Path

from lfrefract.errors import ParameterError

__all__ = [
    "MEMINFO",
    "available_cpus",
    "available_memory",
    "depth_aware_bytes",
    "format_bytes",
    "require_memory",
    "warp_map_bytes",
]

#: Where Linux states the memory available to new allocations (``MemAvailable``, kB).
MEMINFO = Path("/proc/meminfo")


def available_memory() -> tuple[int, str]:
    """Memory available to new allocations now, bytes, and where the figure comes from.

    ``MemAvailable`` in ``/proc/meminfo`` (Linux: free memory plus the page cache and reclaimable
    memory the kernel can give back), else the free physical pages (``os.sysconf``).

    Returns
    -------
    nbytes : int
    source : str
        ``"MemAvailable in /proc/meminfo"`` or ``"free physical pages (sysconf)"``.
    """
    try:
        for line in MEMINFO.read_text(encoding="ascii", errors="replace").splitlines():
            if line.startswith("MemAvailable:"):
                fields = line.split()
                if len(fields) >= 2 and fields[1].isdigit():
                    return int(fields[1]) * 1024, f"MemAvailable in {MEMINFO}"
    except OSError:
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"), "free physical pages (sysconf)"


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the OS has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def format_bytes(nbytes: float) -> str:
    """``nbytes`` in binary units with three significant figures, e.g. ``"71.0 GiB"``."""
    value = float(nbytes)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(value) < 1024.0 or unit == "PiB":
            return f"{value:.0f} {unit}" if unit == "B" else f"{value:.3g} {unit}"
        value /= 1024.0
    raise AssertionError("unreachable")


def require_memory(what: str, nbytes: int, *, reduce: str = "a smaller size") -> None:
    """Refuse an operation whose estimated peak memory exceeds what the machine has available.

    Parameters
    ----------
    what : str
        The operation, for the message (e.g. ``"views: a 1001 x 1001 stack of 92 x 69 px views"``).
    nbytes : int
        Its estimated peak memory, bytes (an estimate from this module or the caller's own).
    reduce : str
        What the user can lower, for the message (e.g. ``"--depth-steps"``, the command line's option).

    Raises
    ------
    ParameterError
        If ``nbytes`` exceeds :func:`available_memory`; the message gives both figures.
    """
    available, source = available_memory()
    if nbytes > available:
        raise ParameterError(
            f"{what} needs about {format_bytes(nbytes)} of memory ({int(nbytes)} bytes, estimated), more than the "
            f"{format_bytes(available)} available ({source}); choose {reduce}"
        )


def depth_aware_bytes(
    *, raw_pixels: int, output_pixels: int, channels: int, depth_steps: int, threads: int, render_chunks: int
) -> int:
    """Estimated peak memory of the depth-aware synthesis of one frame, rays included, bytes.

    What :mod:`lfrefract.synthesis.depth_aware` allocates beyond the warp map (:func:`warp_map_bytes`):

    * the traced rays, 37 bytes per usable raw pixel (float32 origin and direction, int64 raw index,
      int8 quadrant, float32 gain), taken here as every raw pixel, plus the trace's float64
      temporaries, about 200 bytes per raw pixel of one block (at most 2^20 pixels);
    * per frame the rays' values and the kept rays' copies, ``4 channels + 28`` bytes per ray, twice;
    * the plane sweep: the cost volume, ``depth_steps`` float32 per output pixel, about five times
      over while it is aggregated, and per thread one plane's accumulators (``7 + 3 channels``
      float64), refocused image and residuals, ``8 (8 + 4 channels) + 64`` bytes per output pixel;
    * the render: ``render_chunks`` sets of accumulators, ``4 (7 + 3 channels)`` float64 per output
      pixel each, and the image.

    The sweep and the render do not overlap.
    """
    rays = 37 * raw_pixels + 200 * min(raw_pixels, 1 << 20)
    per_frame = 2 * (4 * channels + 28) * raw_pixels
    sweep = 5 * 4 * depth_steps * output_pixels + threads * (8 * (8 + 4 * channels) + 64) * output_pixels
    render = render_chunks * 32 * (7 + 3 * channels) * output_pixels + 8 * channels * output_pixels
    return rays + per_frame + max(sweep, render)


def warp_map_bytes(
    *,
    output_pixels: int,
    raw_pixels: int,
    channels: int,
    supersample: int,
    k: int,
    kdtree: bool,
    workers: int,
    block_pixels: int,
) -> int:
    """Estimated peak memory of building a warp map and applying it once, bytes.

    What ``lfrefract.synthesis.warp_map.build_warp_map`` allocates:

    * the map: about ``k * (1 + s) / 2`` entries per output pixel (the ``s^2`` sub-pixel rays of a
      pixel share most of their ``k`` nearest captured rays: measured 1.7-2.1 k at s = 2 and
      2.3-2.5 k at s = 3 inside the exact coverage, fewer outside), 8 bytes each (int32 index,
      float32 weight), held twice while the blocks are concatenated; plus about 80 bytes per
      output pixel (row pointers, gain, coverage and their block copies);
    * per block of ``block_pixels`` output pixels, one block per worker thread at a time:
      ``s^2 * k`` selection slots of 24 bytes (int64 index, float64 D, and the int32 + float32
      row buffers) and about 300 bytes of ray geometry per sub-pixel ray; with the k-d tree
      search, its queries of ``4 k + 8`` neighbours per ray, about 200 bytes each, and the tree
      over the captured rays, about 200 bytes per raw pixel;
    * the applied image: ``channels`` float32 values per output pixel.

    Measured with tracemalloc on the tiny cameras (2 workers): 0.49-0.83 of the estimate with the
    analytic search (6 000 to 100 000 output pixels, s = 2-3, k = 8-32; the lower figure where
    output pixels are much finer than the lenses, so that the sub-pixel rays share nearly all
    their rays), 0.94-1.12 with the k-d tree (1.86 GB against 1.97 GB at 100 000 pixels, s = 2,
    k = 32).

    Parameters
    ----------
    output_pixels, raw_pixels : int
        Pixels of the refraction-free image and of the raw image.
    channels : int
        Channels of the raw image.
    supersample, k : int
        :class:`lfrefract.synthesis.warp_map.SynthesisOptions` ``supersample`` and ``k``.
    kdtree : bool
        Whether the k-d tree search is used.
    workers : int
        Threads building blocks at once.
    block_pixels : int
        Output pixels per block (``lfrefract.synthesis.warp_map.BLOCK_PIXELS``).

    Returns
    -------
    int
        Bytes.
    """
    s2 = supersample * supersample
    entries = output_pixels * k * (1 + supersample) // 2
    persistent = 2 * 8 * entries + 80 * output_pixels + 4 * channels * output_pixels
    rays_per_block = min(block_pixels, output_pixels) * s2
    per_ray = 24 * k + 300 + (200 * (4 * k + 8) if kdtree else 0)
    transient = min(workers, -(-output_pixels // block_pixels)) * rays_per_block * per_ray
    tree = 200 * raw_pixels if kdtree else 0
    return int(persistent + transient + tree)
