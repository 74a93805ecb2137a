"""The layer contract (docs/design.md, "Layers"): which package may import which, checked on every module.

Two kinds of check:

- Static, over the source of every module under ``lfrefract/`` and ``simulator/`` (imports inside
  functions included): each module's imports of the two packages must be allowed by
  :data:`CONTRACT`. A module that no rule covers fails the test, so a new module must be placed in
  a layer when it is added.
- At run time: importing the core never loads the renderer, and importing the simulator's scene
  model and CLIs does not load Mitsuba until something is rendered.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Layers of the core, lowest first: a layer may import itself and the layers listed for it, no other
# part of lfrefract and never the simulator. Keys and values are module prefixes.
_BASE = ("lfrefract.errors", "lfrefract.validate")
_LOW_FORMATS = ("lfrefract.formats.outputs", "lfrefract.formats.jsonio", "lfrefract.formats.exr")
_VERSION = ("lfrefract.__version__",)  # ``from lfrefract import __version__`` only, not the root's re-exports
CONTRACT: dict[str, tuple[str, ...]] = {
    "lfrefract.errors": (),
    "lfrefract.validate": ("lfrefract.errors",),
    "lfrefract._memory": _BASE,
    "lfrefract.metrics": _BASE,
    "lfrefract.figures": (),  # matplotlib and numpy only
    "lfrefract.formats.outputs": _BASE,
    "lfrefract.formats.jsonio": (*_BASE, "lfrefract.formats.outputs"),
    "lfrefract.formats.exr": (*_BASE, "lfrefract.formats.outputs", "lfrefract.formats.jsonio"),
    "lfrefract.formats.ply": (*_BASE, *_LOW_FORMATS),
    "lfrefract.formats.mosaic": (*_BASE, *_LOW_FORMATS),
    "lfrefract.formats.lytro": (*_BASE, *_LOW_FORMATS, "lfrefract.formats.mosaic", "lfrefract.optics"),
    "lfrefract.formats.whites": (
        *_BASE,
        *_LOW_FORMATS,
        "lfrefract.formats.mosaic",
        "lfrefract.formats.lytro",
        "lfrefract.optics",
    ),
    "lfrefract.optics": (*_BASE, "lfrefract.optics"),
    "lfrefract.formats.flatport": (*_BASE, *_LOW_FORMATS, "lfrefract.optics"),
    "lfrefract.formats.pfm": (*_BASE, "lfrefract.formats.outputs"),
    "lfrefract.formats.paramfile": (*_BASE, *_LOW_FORMATS, "lfrefract.optics", "lfrefract.formats.flatport"),
    "lfrefract.synthesis": (
        *_BASE,
        *_LOW_FORMATS,
        *_VERSION,
        "lfrefract._memory",
        "lfrefract.formats.mosaic",
        "lfrefract.optics",
    ),
    "lfrefract.formats.viewstack": (
        *_BASE,
        *_LOW_FORMATS,
        *_VERSION,
        "lfrefract.optics",
        "lfrefract.synthesis",
        "lfrefract.formats.pfm",
    ),
    "lfrefract.stereo": (*_BASE, "lfrefract.optics"),
    "lfrefract.calibration": (
        *_BASE,
        *_LOW_FORMATS,
        "lfrefract._memory",
        "lfrefract.optics",
        "lfrefract.synthesis",
    ),
    "lfrefract.formats.capture": (
        *_BASE,
        *_LOW_FORMATS,
        "lfrefract.formats.mosaic",
        "lfrefract.formats.lytro",
        "lfrefract.formats.whites",
        "lfrefract.optics",
        "lfrefract.formats.flatport",
        "lfrefract.formats.paramfile",
        "lfrefract.calibration",
        "lfrefract.synthesis",
    ),
    "lfrefract.methods": (*_BASE, *_LOW_FORMATS, "lfrefract.optics", "lfrefract.synthesis", "lfrefract.calibration"),
    # The package roots re-export the public API; the CLIs may use all of the core.
    "lfrefract.formats": (),
    "lfrefract": ("lfrefract",),
    "lfrefract.cli": ("lfrefract",),
    "lfrefract.__main__": ("lfrefract",),
    # The simulator uses the whole core except its CLI (but the pipeline experiment, PRIVATE_TO); its own
    # scene model (config, assets, geometry)
    # never reaches the Mitsuba side, and only the CLI entry points import the CLI.
    "simulator": ("lfrefract", "simulator"),
}

#: Modules no module but the listed ones may import.
PRIVATE_TO: dict[str, tuple[str, ...]] = {
    # The pipeline experiment runs the core's commands as a user would (its record is the commands).
    "lfrefract.cli": ("lfrefract.__main__", "simulator.experiments.pipeline"),
    "simulator.cli": ("simulator.__main__",),
}

#: The simulator's scene model: what a scene holds, without Mitsuba. It must not import these.
SCENE_MODEL = ("simulator.config", "simulator.assets", "simulator.geometry")
MITSUBA_SIDE = ("simulator.scene", "simulator.sensor", "simulator.interface", "simulator.backend", "simulator.render")


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    found = {}
    for package in ("lfrefract", "simulator"):
        for path in sorted((ROOT / package).rglob("*.py")):
            found[_module_name(path)] = path
    return found


def _imports(name: str, path: Path) -> set[str]:
    """Absolute names imported by the module (``from a import b`` gives ``a.b``), relative ones resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join([*anchor, base] if base else anchor)
            out.update(f"{base}.{alias.name}" for alias in node.names)
    return out


def _within(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def _rule(name: str) -> str | None:
    matches = [key for key in CONTRACT if _within(name, key)]
    return max(matches, key=len) if matches else None


def _ours(imported: str) -> bool:
    return imported.split(".")[0] in ("lfrefract", "simulator")


MODULES = _modules()


def test_every_module_has_a_layer():
    assert len(MODULES) > 60
    assert [name for name in MODULES if _rule(name) is None] == []


@pytest.mark.parametrize("name", sorted(MODULES))
def test_module_imports_follow_the_layers(name):
    rule = _rule(name)
    allowed = (rule, *CONTRACT[rule]) if rule not in ("lfrefract.formats",) else ()
    bad = []
    for imported in sorted(_imports(name, MODULES[name])):
        if not _ours(imported):
            continue
        head = ".".join(imported.split(".")[:2])
        if head.startswith("lfrefract.") and head not in MODULES and head != "lfrefract.__version__":
            # ``from lfrefract import Pose``: a name re-exported by the root, which only the CLIs and the
            # simulator may use (the root imports most of the core).
            ok = rule in ("lfrefract", "lfrefract.cli", "lfrefract.__main__", "simulator")
        else:
            ok = any(_within(imported, prefix) for prefix in allowed) or (
                rule == "lfrefract" and imported.startswith("lfrefract.")
            )
        if name.startswith("lfrefract") and imported.startswith("simulator"):
            ok = False
        for private, users in PRIVATE_TO.items():
            if _within(imported, private) and name not in users and not _within(name, private):
                ok = False
        if any(_within(name, m) for m in SCENE_MODEL) and any(_within(imported, m) for m in MITSUBA_SIDE):
            ok = False
        if not ok:
            bad.append(imported)
    assert bad == [], f"{name} ({MODULES[name].relative_to(ROOT)}) imports outside its layer {rule!r}"


def test_the_contract_catches_a_violation(tmp_path):
    """The check itself: a core module importing the simulator, or optics importing synthesis, is caught."""
    module = tmp_path / "probe.py"
    module.write_text("from simulator.config import SceneConfig\ndef f():\n    from lfrefract.synthesis import views\n")
    imported = _imports("lfrefract.optics.probe", module)
    assert imported == {"simulator.config.SceneConfig", "lfrefract.synthesis.views"}
    allowed = ("lfrefract.optics", *CONTRACT["lfrefract.optics"])
    assert [i for i in imported if not any(_within(i, p) for p in allowed)] != []


def test_core_imports_no_renderer():
    code = (
        "import sys, lfrefract, lfrefract.cli, lfrefract.formats.capture\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit', 'simulator'))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""


def test_simulator_imports_mitsuba_only_when_asked():
    code = (
        "import sys, simulator.config, simulator.scene, simulator.job, simulator.cli\n"
        "print(','.join(sorted(m for m in sys.modules if m.split('.')[0] in ('mitsuba', 'drjit'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == ""
