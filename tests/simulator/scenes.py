"""Small scene configs for simulator tests (not fixtures: plain builders).

The chessboard set-ups and their ground truth are in :mod:`simulator.boards`.
"""

from __future__ import annotations

from simulator.config import SceneConfig, parse_scene

LIGHTS = [
    {"type": "point", "position_m": [-0.2, -0.3, 0.15], "intensity_w_sr": 0.4},
    {"type": "point", "position_m": [0.25, -0.1, 0.1], "intensity_w_sr": 0.3},
]


def scene(
    *,
    base_dir=".",
    port: dict | None,
    objects: list[dict],
    lights: list[dict] | None = None,
    spp: int = 16,
    seed: int = 0,
    camera: str | dict = "tiny",
) -> SceneConfig:
    """A scene with the given port table (None: no port), objects and (default) point lights.

    ``camera`` is a preset name or a full camera table (every field of
    ``LightFieldCamera.to_dict()``). Relative mesh paths are resolved against ``base_dir``.
    """
    data = {
        "camera": {"preset": camera} if isinstance(camera, str) else camera,
        "render": {"spp": spp, "seed": seed},
        "light": LIGHTS if lights is None else lights,
        "object": objects,
    }
    if port is not None:
        data["port"] = port
    return parse_scene(data, base_dir=base_dir, source="<test>")


def port(tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0, thickness_m: float = 0.006) -> dict:
    """A port table: 20 mm away, given tilt and thickness, air / glass 1.5 / water 1.333."""
    return {
        "distance_m": 0.02,
        "thickness_m": thickness_m,
        "tilt_x_deg": tilt_x_deg,
        "tilt_y_deg": tilt_y_deg,
        "n_air": 1.0,
        "n_glass": 1.5,
        "n_water": 1.333,
    }
