"""Synthesis: images from a raw light-field image.

- :mod:`~lfrefract.synthesis.warp_map`: the refraction-free image (the paper's method), a sparse
  map from raw pixels to a central-projection image, built once per camera, port and output.
- :mod:`~lfrefract.synthesis.views`: naive views, sub-aperture views and view stacks (no port model).
"""

from lfrefract.synthesis.views import ViewStack, naive_view, subaperture_stack, subaperture_view
from lfrefract.synthesis.warp_map import SynthesisOptions, WarpMap, build_warp_map

__all__ = [
    "SynthesisOptions",
    "ViewStack",
    "WarpMap",
    "build_warp_map",
    "naive_view",
    "subaperture_stack",
    "subaperture_view",
]
