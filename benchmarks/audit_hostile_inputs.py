"""Hostile-input audit: hundreds of bad inputs and faults given to both command lines, classified.

Each case runs one command (``lfrefract`` or ``lfsim``) in a subprocess on files this script makes
(small renders of the ``tiny`` and ``tiny-2x`` cameras, their Lytro files, white images, board
captures and a calibrated camera file) and edits (forged Lytro metadata, edited camera files,
duplicated views, a full disk, signals mid-run ...). What it expects is written beside each case:
a refusal that names given words (the option, the file, the key), or a result that passes a check.
Every outcome falls in one class:

``ok``
    as expected.
``crash``
    a Python traceback, an exit status other than 0 / 2 / 130 / 143, a signal, a time-out, or the
    memory limit (each command runs under ``--memory-gb`` of address space).
``silent``
    a silent wrong result: exit 0 where a refusal was due, a result that fails its check, an input
    changed, or files left half-written by a refusal.
``unclear``
    a refusal (exit 2, one line) that does not name what it should.
``refused``
    a refusal where a result was due.

The files are made once in ``--work`` (``fixtures/``, about 3 minutes on two cores) and reused;
each case works in a folder of its own under ``--work``/``cases``. ``--tree`` picks the source tree
whose commands are audited (``PYTHONPATH``), so two versions can be compared on the same files::

    python benchmarks/audit_hostile_inputs.py --work /tmp/audit                   # this tree
    git worktree add /tmp/old <commit>
    python benchmarks/audit_hostile_inputs.py --work /tmp/audit --tree /tmp/old   # another

It prints one line per case that is not ``ok`` and the counts per group and class; ``--json``
writes every case's outcome.
"""

from __future__ import annotations

import argparse
import collections
import concurrent.futures
import dataclasses
import hashlib
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SQUARES = ("7", "5")


# =============================================================================== cases
@dataclasses.dataclass(frozen=True, kw_only=True)
class Case:
    """One hostile input.

    ``argv`` starts with ``lfrefract`` or ``lfsim``; ``{F}`` in an argument is the fixtures folder
    and ``{C}`` the case's own folder. ``expect`` is ``"refuse"`` (exit 2 naming every word of
    ``says``, case-insensitive; any one of a tuple inside it), ``"ok"`` (exit 0, then ``check``
    returns None or the problem) or ``"either"`` (a refusal naming ``says`` or a result passing
    ``check``). ``setup`` prepares the case folder; ``inputs`` are files (under ``{F}`` or ``{C}``)
    that must be unchanged afterwards. ``signal_after_s`` sends ``signum`` that long after the start
    (``expect`` then is ``"interrupt"``: a clean end, exit 128 + signum, one line, no traceback).
    """

    group: str
    name: str
    argv: tuple[str, ...]
    expect: str = "refuse"
    says: tuple = ()
    check: Callable[[Path, str], str | None] | None = None
    setup: Callable[[Path, Path], None] | None = None
    inputs: tuple[str, ...] = ()
    signal_after_s: float | None = None
    signum: int = signal.SIGINT
    timeout_s: float = 300.0
    after: Callable[[Path, Path, dict], str | None] | None = None


def _fmt(text: str, fixtures: Path, folder: Path) -> str:
    return text.replace("{F}", str(fixtures)).replace("{C}", str(folder))


# =============================================================================== fixtures
def _run(argv: list[str], *, env: dict, cwd: Path, timeout: float = 1800) -> None:
    result = subprocess.run(argv, env=env, cwd=cwd, capture_output=True, text=True, timeout=timeout)
    if result.returncode != 0:
        raise SystemExit(f"fixture command failed ({result.returncode}): {' '.join(argv)}\n{result.stderr[-3000:]}")


_BOARDS_PY = r"""
import sys
from pathlib import Path
from lfrefract import camera_preset, virtual_camera_for
from simulator import boards
from simulator.job import render_job
root = Path(sys.argv[1])
view = virtual_camera_for(camera_preset(boards.CAMERA))
sizes = []
for k, table in enumerate(boards.in_air_boards(view)[:5]):
    render_job(boards.in_air_board_scene(table), root / "air" / f"b{k}", progress=False, write_previews=False)
    sizes.append(table["square_size_m"])
(root / "air" / "sizes.txt").write_text(" ".join(map(repr, sizes)))
tilt = (25.0, 10.0)
tables = boards.calibration_boards(tilt, 0.2, virtual_camera_for(boards.empty_scene(tilt).camera))
for k, table in enumerate(tables):
    scene = boards.board_scene(tilt, table, spp=16, seed=k)
    render_job(scene, root / "port" / f"b{k}", progress=False, write_previews=False)
(root / "port" / "size.txt").write_text(repr(tables[0]["square_size_m"]))
"""

_ILLUM_RAW_PY = r"""
import json, sys
from pathlib import Path
from lfrefract.formats.lytro import pack_10bit, read_lfr
lytro = read_lfr(sys.argv[1])
out = Path(sys.argv[2])
out.with_suffix(".raw").write_bytes(pack_10bit(lytro.mosaic.counts))
out.with_suffix(".txt").write_text(json.dumps(lytro.metadata, indent=1))
"""


#: The file that marks a --work folder as this script's: only in such a folder does it delete anything
#: (an unfinished fixture set, a case's earlier folder).
WORK_MARKER = ".audit-hostile-inputs"


def claim_work_folder(work: Path) -> None:
    """Make ``work`` this script's folder, or refuse a folder that holds anything else: everything the
    script removes lies under it, so a user's folder given by mistake is never touched."""
    if work.exists() and not (work / WORK_MARKER).exists() and any(work.iterdir()):
        raise SystemExit(f"--work {str(work)!r} holds files this script did not write: give an empty or new folder")
    work.mkdir(parents=True, exist_ok=True)
    (work / WORK_MARKER).touch()


def build_fixtures(fixtures: Path, tree: Path) -> None:
    """Make every file the cases start from with the commands of ``tree`` (once; a finished set is
    marked by ``done``)."""
    if (fixtures / "done").exists():
        return
    if fixtures.exists():
        shutil.rmtree(fixtures)
    fixtures.mkdir(parents=True)
    env = _environment(tree)
    py = sys.executable
    lfsim, lfr = [py, "-m", "simulator.cli"], [py, "-m", "lfrefract"]
    quiet = ["--quiet", "--no-previews"]
    steps = [
        ("capture", [*lfsim, "render", "--out", "cap", "--spp", "4", *quiet]),
        ("Lytro capture", [*lfsim, "render", "--out", "lfr", "--spp", "4", "--sensor", "tiny", "--lfr", *quiet]),
        ("white render", [*lfsim, "render", "white", "--out", "white", "--spp", "4", *quiet]),
        ("white images", [*lfsim, "whites", "--camera", "tiny", "--frames", "4", "--spp", "8", "--out", "whites"]),
        ("double-Gauss capture", [*lfsim, "render", "--out", "dg", "--spp", "4", "--lens", "double-gauss", *quiet]),
        ("boards", [py, "-c", _BOARDS_PY, str(fixtures)]),
        ("Illum-style raw", [py, "-c", _ILLUM_RAW_PY, str(fixtures / "lfr" / "capture.lfr"), "capture"]),
    ]
    for what, argv in steps:
        print(f"fixtures: {what} ...", flush=True)
        _run(argv, env=env, cwd=fixtures)
    sizes = (fixtures / "air" / "sizes.txt").read_text().split()
    air = [str(fixtures / "air" / f"b{k}" / "raw.exr") for k in range(5)]
    print("fixtures: camera calibration ...", flush=True)
    argv = [*lfr, "calibrate", "camera", *air, "--squares", *SQUARES, "--square-size-m", *sizes]
    _run([*argv, "--out", "camera.json"], env=env, cwd=fixtures)
    port = json.loads((fixtures / "cap" / "meta.json").read_text())["port"]
    (fixtures / "port.json").write_text(json.dumps({"schema_version": 1, "port": port}))
    (fixtures / "done").write_text("")


# =============================================================================== case helpers
def _json(path: Path) -> dict:
    return json.loads(path.read_text())


def _copy_tree(source: Path, target: Path) -> None:
    shutil.copytree(source, target, dirs_exist_ok=True)


def _exr(path: Path):
    import OpenEXR

    with OpenEXR.File(str(path)) as f:
        channels = f.channels()
        return {name: channels[name].pixels for name in channels}


def _finite_output(out: str) -> Callable[[Path, str], str | None]:
    """A check: the EXR ``out`` (in the case folder) exists and holds finite values somewhere."""

    def check(folder: Path, stdout: str) -> str | None:
        import numpy as np

        path = folder / out
        if not path.is_file():
            return f"no output {out}"
        arrays = [np.asarray(a, dtype=float) for a in _exr(path).values()]
        if not any(np.isfinite(a).any() for a in arrays):
            return f"{out} holds no finite value"
        if any(np.isinf(a).any() for a in arrays):
            return f"{out} holds infinite values"
        return None

    return check


def _edit_json(source: str, target: str, edit: Callable[[dict], None]) -> Callable[[Path, Path], None]:
    def setup(fixtures: Path, folder: Path) -> None:
        data = _json(Path(_fmt(source, fixtures, folder)))
        edit(data)
        Path(_fmt(target, fixtures, folder)).write_text(json.dumps(data, allow_nan=True))

    return setup


def _set(path: str, value) -> Callable[[dict], None]:
    """An edit of a nested key (``a.b.c``); ``value`` ``_DELETE`` removes it."""

    def edit(data: dict) -> None:
        *parents, last = path.split(".")
        node = data
        for key in parents:
            node = node[key]
        if value is _DELETE:
            node.pop(last, None)
        else:
            node[last] = value

    return edit


_DELETE = object()


def _illum_pair(edit: Callable[[dict], None] | None = None) -> Callable[[Path, Path], None]:
    """The Illum-style ``capture.raw`` + ``capture.txt`` in the case folder, its metadata edited."""

    def setup(fixtures: Path, folder: Path) -> None:
        shutil.copy(fixtures / "capture.raw", folder / "capture.raw")
        data = _json(fixtures / "capture.txt")
        if edit is not None:
            edit(data)
        (folder / "capture.txt").write_text(json.dumps(data, allow_nan=True))

    return setup


def _combined(*setups: Callable[[Path, Path], None]) -> Callable[[Path, Path], None]:
    def setup(fixtures: Path, folder: Path) -> None:
        for s in setups:
            s(fixtures, folder)

    return setup


def _raw_exr(make) -> Callable[[Path, Path], None]:
    """A capture folder ``cap`` in the case folder: the fixture's meta.json and ``make(raw)`` as raw.exr."""

    def setup(fixtures: Path, folder: Path) -> None:
        sys.path.insert(0, os.environ.get("AUDIT_TREE", str(REPO)))
        from lfrefract.formats.exr import read_exr, write_exr

        (folder / "cap").mkdir()
        shutil.copy(fixtures / "cap" / "meta.json", folder / "cap" / "meta.json")
        raw = read_exr(fixtures / "cap" / "raw.exr")
        write_exr(folder / "cap" / "raw.exr", make(raw), role="raw")

    return setup


# =============================================================================== the cases
def lytro_cases() -> list[Case]:
    """Forged Lytro containers and metadata (Illum ``.lfr`` and ``.raw`` + ``.txt``)."""
    cases = []
    lfr = "{F}/lfr/capture.lfr"

    def container(name: str, make: Callable[[bytes], bytes]) -> Case:
        def setup(fixtures: Path, folder: Path) -> None:
            (folder / "x.lfr").write_bytes(make((fixtures / "lfr" / "capture.lfr").read_bytes()))

        return Case(
            group="lytro",
            name=f"container-{name}",
            argv=("lfrefract", "naive", "{C}/x.lfr", "--out", "{C}/o.exr"),
            says=("x.lfr",),
            setup=setup,
        )

    cases += [
        container("empty", lambda b: b""),
        container("10-bytes-magic", lambda b: b[:10]),
        container("magic-only", lambda b: b[:8]),
        container("header-only", lambda b: b[:16]),
        container("half", lambda b: b[: len(b) // 2]),
        container("trailing-garbage", lambda b: b + b"garbage!" * 5),
        container("wrong-magic", lambda b: b"\x89PNG\r\n\x1a\n" + b[8:]),
        container("flipped-metadata-byte", lambda b: b.replace(b'"image"', b'"imagf"', 1)),
        container("flipped-last-byte", lambda b: b[:-1] + bytes([b[-1] ^ 0xFF])),
        container("text", lambda b: b"this is not a light field\n" * 10),
        container("doubled", lambda b: b + b),
    ]
    # The last section's padding cut short: every byte of every section is there (a reader may
    # take it or refuse it; either way it must not give another image).
    cases.append(
        dataclasses.replace(
            container("one-byte-short", lambda b: b[:-1]), expect="either", check=_finite_output("o.exr")
        )
    )
    cases.append(
        Case(
            group="lytro",
            name="lfr-is-a-directory",
            argv=("lfrefract", "naive", "{C}/d.lfr", "--out", "{C}/o.exr"),
            says=("d.lfr",),
            setup=lambda F, C: (C / "d.lfr").mkdir(),
        )
    )
    cases.append(
        Case(
            group="lytro",
            name="lfr-missing",
            argv=("lfrefract", "naive", "{C}/none.lfr", "--out", "{C}/o.exr"),
            says=("none.lfr",),
        )
    )
    cases.append(
        Case(
            group="lytro",
            name="lfr-symlink-loop",
            argv=("lfrefract", "naive", "{C}/loop.lfr", "--out", "{C}/o.exr"),
            says=("loop.lfr",),
            setup=lambda F, C: (C / "loop.lfr").symlink_to(C / "loop.lfr"),
        )
    )
    cases.append(
        Case(
            group="lytro",
            name="lfr-reference",
            argv=("lfrefract", "naive", lfr, "--out", "{C}/o.exr"),
            expect="ok",
            check=_finite_output("o.exr"),
            inputs=(lfr,),
        )
    )
    cases.append(
        Case(
            group="lytro",
            name="raw-pair-reference",
            argv=("lfrefract", "naive", "{C}/capture.raw", "--out", "{C}/o.exr"),
            expect="ok",
            check=_finite_output("o.exr"),
            setup=_illum_pair(),
        )
    )
    # Metadata keys: each read key missing, not a number, NaN, and out of its domain.
    numeric = {
        "devices.lens.focalLength": (0, -0.01),
        "devices.lens.exitPupilOffset.z": (0, -0.01),
        "devices.lens.fNumber": (0, -2),
        "devices.mla.lensPitch": (0, -1e-5),
        "devices.mla.sensorOffset.z": (0, -1e-5),
        "devices.mla.rotation": (1e9,),
        "devices.mla.sensorOffset.x": (),  # any offset is a lattice (taken modulo the pitch)
        "devices.sensor.pixelPitch": (0, -1e-6),
        "image.width": (0, -8, 7),
        "image.height": (0, -8),
        "image.pixelPacking.bitsPerPixel": (12, 0),
        "image.pixelFormat.black.r": (-1, 5000),
        "image.pixelFormat.white.gr": (0, 100000),
    }
    for key, bad in numeric.items():
        leaf = key.split(".")[-1]
        variants = [("missing", _DELETE), ("string", "abc"), ("nan", float("nan")), ("null", None)]
        variants += [(f"value-{v}", v) for v in bad]
        for label, value in variants:
            cases.append(
                Case(
                    group="lytro-metadata",
                    name=f"{key}-{label}",
                    argv=("lfrefract", "naive", "{C}/capture.raw", "--out", "{C}/o.exr"),
                    says=("capture.raw", (leaf, key.split(".")[-2] if leaf in "xyzrgrgbb" else leaf)),
                    setup=_illum_pair(_set(key, value)),
                )
            )

    def swap_size(data: dict) -> None:
        image = data["image"]
        image["width"], image["height"] = image["height"], image["width"]

    contradictions = {
        "width-height-swapped": (swap_size, ("width", "height")),
        "ccm-all-zero": (_set("image.color.ccm", [0.0] * 9), ("ccm",)),
        "ccm-eight-values": (_set("image.color.ccm", [1.0] * 8), ("ccm",)),
        "ccm-strings": (_set("image.color.ccm", ["a"] * 9), ("ccm",)),
        "ccm-nan": (_set("image.color.ccm", [float("nan")] * 9), ("ccm",)),
        "ccm-singular": (_set("image.color.ccm", [1, 1, 1, 1, 1, 1, 1, 1, 1]), ("ccm",)),
        "gain-missing-b": (_set("image.color.whiteBalanceGain.b", _DELETE), ("whiteBalanceGain",)),
        "gain-string": (_set("image.color.whiteBalanceGain.r", "red"), ("whiteBalanceGain",)),
        "gain-zero": (_set("image.color.whiteBalanceGain.r", 0.0), ("whiteBalanceGain",)),
        "gain-negative": (_set("image.color.whiteBalanceGain.gb", -1.0), ("whiteBalanceGain",)),
        "gain-nan": (_set("image.color.whiteBalanceGain.b", float("nan")), ("whiteBalanceGain",)),
        "gain-not-a-table": (_set("image.color.whiteBalanceGain", 1.5), ("whiteBalanceGain",)),
        "black-at-white": (
            lambda d: [
                _set(f"image.pixelFormat.black.{c}", d["image"]["pixelFormat"]["white"][c])(d)
                for c in ("r", "gr", "gb", "b")
            ],
            ("black",),
        ),
        "mosaic-unknown": (_set("image.mosaic.upperLeftPixel", "q"), ("mosaic",)),
        "tiling-unknown": (_set("devices.mla.tiling", "octagonal"), ("tiling",)),
        "zoom-step-string": (_set("devices.lens.zoomStep", "wide"), ("zoomStep",)),
        "endianness-big": (_set("image.pixelPacking.endianness", "big"), ("endianness", "packing")),
        "metadata-not-json": (None, ("capture.txt",)),
        "metadata-list": (None, ("capture.txt",)),
    }
    for label, (edit, words) in contradictions.items():
        if label == "metadata-not-json":
            setup = _combined(_illum_pair(), lambda F, C: (C / "capture.txt").write_text("{not json"))
        elif label == "metadata-list":
            setup = _combined(_illum_pair(), lambda F, C: (C / "capture.txt").write_text("[1, 2]"))
        else:
            setup = _illum_pair(edit)
        cases.append(
            Case(
                group="lytro-metadata",
                name=label,
                argv=("lfrefract", "naive", "{C}/capture.raw", "--out", "{C}/o.exr"),
                says=words,
                setup=setup,
            )
        )
    return cases


def _white_folder_with(extra: Callable[[Path, Path], None]) -> Callable[[Path, Path], None]:
    def setup(fixtures: Path, folder: Path) -> None:
        _copy_tree(fixtures / "whites", folder / "whites")
        extra(fixtures, folder)

    return setup


def _whites_index(fixtures: Path) -> list[Path]:
    return sorted((fixtures / "whites").glob("*.raw"))


def white_cases() -> list[Case]:
    """``--white``: folders and files that are no white image of this capture."""
    lfr = "{F}/lfr/capture.lfr"
    synth = ("lfrefract", "naive", lfr, "--out", "{C}/o.exr", "--white")
    cases = [
        Case(
            group="whites",
            name="reference-folder",
            argv=(*synth, "{F}/whites"),
            expect="ok",
            check=_finite_output("o.exr"),
            inputs=(lfr,),
        )
    ]

    def capture_as_white(fixtures: Path, folder: Path) -> None:
        # The capture itself, as an Illum .raw + .txt with a name that sorts first.
        shutil.copy(fixtures / "capture.raw", folder / "whites" / "0000-capture.raw")
        shutil.copy(fixtures / "capture.txt", folder / "whites" / "0000-capture.txt")

    cases.append(
        Case(
            group="whites",
            name="a-capture-in-the-white-folder",
            argv=(*synth, "{C}/whites"),
            expect="either",
            says=("0000-capture",),
            check=_uses_a_real_white,
            setup=_white_folder_with(capture_as_white),
        )
    )

    def white_edit(name: str, change: Callable[[Path, Path], None], says=(), expect="refuse", check=None) -> Case:
        return Case(
            group="whites",
            name=name,
            argv=(*synth, "{C}/w.raw"),
            expect=expect,
            says=says or ("w.raw",),
            check=check,
            setup=change,
        )

    def first_white(fixtures: Path, folder: Path) -> tuple[Path, Path]:
        raw = _whites_index(fixtures)[0]
        meta = next(p for p in (raw.with_suffix(".txt"), raw.with_suffix(".json")) if p.exists())
        shutil.copy(raw, folder / "w.raw")
        shutil.copy(meta, folder / ("w" + meta.suffix))
        return folder / "w.raw", folder / ("w" + meta.suffix)

    def counts_edit(fill: str) -> Callable[[Path, Path], None]:
        def setup(fixtures: Path, folder: Path) -> None:
            raw, meta = first_white(fixtures, folder)
            sys.path.insert(0, os.environ.get("AUDIT_TREE", str(REPO)))
            import numpy as np

            from lfrefract.formats.lytro import pack_10bit

            data = _json(meta)
            fmt = data["image"]["pixelFormat"]
            h, w = data["image"]["height"], data["image"]["width"]
            level = {"black": fmt["black"]["r"], "white": fmt["white"]["r"], "mid": 300}[fill]
            raw.write_bytes(pack_10bit(np.full((h, w), level, dtype=np.uint16)))

        return setup

    def steps_edit(zoom: int) -> Callable[[Path, Path], None]:
        def setup(fixtures: Path, folder: Path) -> None:
            _, meta = first_white(fixtures, folder)
            data = _json(meta)
            data["devices"]["lens"]["zoomStep"] = zoom
            meta.write_text(json.dumps(data))

        return setup

    cases += [
        white_edit("no-light", counts_edit("black"), says=("w.raw", ("no light", "dark", "black"))),
        white_edit("all-saturated", counts_edit("white"), says=("w.raw", "saturat")),
        white_edit("uniform-no-micro-images", counts_edit("mid"), says=("w.raw",)),
        # The same optics under another step number: used or refused, but never without a word.
        white_edit(
            "zoom-step-far",
            steps_edit(99999),
            says=("zoom", "99999"),
            expect="either",
            check=lambda c, out: None if "99999" in out else "no word of the white's zoom step",
        ),
    ]

    def other_size(fixtures: Path, folder: Path) -> None:
        raw, meta = first_white(fixtures, folder)
        data = _json(meta)
        data["image"]["width"] -= 8
        meta.write_text(json.dumps(data))
        sys.path.insert(0, os.environ.get("AUDIT_TREE", str(REPO)))
        import numpy as np

        from lfrefract.formats.lytro import pack_10bit

        raw.write_bytes(pack_10bit(np.full((data["image"]["height"], data["image"]["width"]), 300, np.uint16)))

    cases.append(white_edit("another-sensor-size", other_size, says=("w.raw", ("size", "width", "shape"))))
    cases += [
        Case(
            group="whites",
            name="symlink-loop",
            argv=(*synth, "{C}/loop"),
            says=("loop",),
            setup=lambda F, C: (C / "loop").symlink_to(C / "loop"),
        ),
        Case(group="whites", name="missing", argv=(*synth, "{C}/none"), says=("none",)),
        Case(
            group="whites",
            name="empty-folder",
            argv=(*synth, "{C}/empty"),
            says=("empty",),
            setup=lambda F, C: (C / "empty").mkdir(),
        ),
        Case(
            group="whites",
            name="folder-of-text",
            argv=(*synth, "{C}/junk"),
            says=("junk",),
            setup=lambda F, C: ((C / "junk").mkdir(), (C / "junk" / "a.txt").write_text("hello")),
        ),
        Case(group="whites", name="the-capture-itself", argv=(*synth, lfr), says=("capture.lfr",)),
        Case(
            group="whites",
            name="exr-render-folder-raw",
            argv=(*synth, "{F}/white/raw.exr"),
            expect="either",
            says=("raw.exr",),
            check=_finite_output("o.exr"),
        ),
        Case(
            group="whites",
            name="white-for-an-exr-capture",
            argv=("lfrefract", "naive", "{F}/cap/raw.exr", "--out", "{C}/o.exr", "--white", "{F}/whites"),
            says=("--white",),
        ),
        Case(
            group="whites",
            name="truncated-white",
            argv=(*synth, "{C}/w.raw"),
            says=("w.raw",),
            setup=lambda F, C: (
                first_white(F, C),
                (C / "w.raw").write_bytes((C / "w.raw").read_bytes()[:1000]),
            ),
        ),
    ]
    return cases


def _uses_a_real_white(folder: Path, stdout: str) -> str | None:
    """The naive view developed with a white from the folder: its mean must be that of the
    reference run's (within 30 %), not the capture-as-white's."""
    import numpy as np

    out = folder / "o.exr"
    if not out.exists():
        return "no output"
    values = np.concatenate([np.asarray(a, float).ravel() for a in _exr(out).values()])
    reference = folder.parent / "whites-reference-folder" / "o.exr"
    if not reference.exists():
        return None
    expected = np.nanmean(np.concatenate([np.asarray(a, float).ravel() for a in _exr(reference).values()]))
    mean = np.nanmean(values)
    return (
        None if abs(mean - expected) < 0.3 * abs(expected) else f"mean {mean:.3g}, with the true white {expected:.3g}"
    )


def _air(k: int) -> str:
    return f"{{F}}/air/b{k}/raw.exr"


def _port(k: int) -> str:
    return f"{{F}}/port/b{k}/raw.exr"


def calibration_cases(fixtures: Path) -> list[Case]:
    """``lfrefract calibrate``: repeated views, implausible boards and options."""
    sizes = (fixtures / "air" / "sizes.txt").read_text().split() if (fixtures / "air").exists() else ["0.01"] * 5
    port_size = (fixtures / "port" / "size.txt").read_text().strip() if (fixtures / "port").exists() else "0.01"
    cam = ("lfrefract", "calibrate", "camera")
    approx = ("lfrefract", "calibrate", "approx")
    port = ("lfrefract", "calibrate", "port")
    board = ("--squares", *SQUARES)
    out = ("--out", "{C}/o.json")
    cases = []

    def copy_of(source: str, name: str) -> Callable[[Path, Path], None]:
        def setup(fixtures: Path, folder: Path) -> None:
            src = Path(_fmt(source, fixtures, folder)).parent
            shutil.copytree(src, folder / name)

        return setup

    def link_of(source: str, name: str) -> Callable[[Path, Path], None]:
        def setup(fixtures: Path, folder: Path) -> None:
            (folder / name).symlink_to(Path(_fmt(source, fixtures, folder)).parent)

        return setup

    a0 = _air(0)
    cases += [
        Case(
            group="calibration",
            name="camera-one-view-thrice",
            argv=(*cam, a0, a0, a0, *board, "--square-size-m", sizes[0], sizes[0], sizes[0], *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
        ),
        Case(
            group="calibration",
            name="camera-view-and-copies",
            argv=(*cam, a0, "{C}/c1/raw.exr", "{C}/c2/raw.exr", *board, "--square-size-m", *[sizes[0]] * 3, *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
            setup=_combined(copy_of(a0, "c1"), copy_of(a0, "c2")),
        ),
        Case(
            group="calibration",
            name="camera-view-and-symlink",
            argv=(*cam, a0, _air(1), "{C}/l/raw.exr", *board, "--square-size-m", sizes[0], sizes[1], sizes[0], *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
            setup=link_of(a0, "l"),
        ),
        Case(
            group="calibration",
            name="approx-one-view-thrice",
            argv=(*approx, _port(0), _port(0), _port(0), *board, "--square-size-m", port_size, *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
        ),
        Case(
            group="calibration",
            name="approx-view-and-copies",
            argv=(*approx, _port(0), "{C}/c1/raw.exr", "{C}/c2/raw.exr", *board, "--square-size-m", port_size, *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
            setup=_combined(copy_of(_port(0), "c1"), copy_of(_port(0), "c2")),
        ),
        Case(
            group="calibration",
            name="port-one-view-twice",
            argv=(*port, _port(0), _port(0), *board, "--square-size-m", port_size, *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
        ),
        Case(
            group="calibration",
            name="port-view-and-copy",
            argv=(*port, _port(0), "{C}/c1/raw.exr", *board, "--square-size-m", port_size, *out),
            says=(("same", "duplicate", "repeat", "distinct"),),
            setup=copy_of(_port(0), "c1"),
        ),
        Case(
            group="calibration",
            name="port-in-air-boards",
            argv=(*port, *[_air(k) for k in range(5)], *board, "--square-size-m", *sizes, *out),
            says=(("air", "refraction", "port"),),
            timeout_s=600,
        ),
        Case(
            group="calibration",
            name="port-wrong-squares",
            argv=(*port, *[_port(k) for k in range(6)], "--squares", "6", "4", "--square-size-m", port_size, *out),
            says=("--squares",),
            timeout_s=600,
        ),
    ]
    views6 = [_port(k) for k in range(6)]
    for label, value in (
        ("huge", "1e9"),
        ("zero", "0"),
        ("negative", "-0.01"),
        ("nan", "nan"),
        ("inf", "inf"),
        ("tiny", "1e-9"),
    ):
        for command, views in (("approx", views6), ("port", views6)):
            cases.append(
                Case(
                    group="calibration",
                    name=f"{command}-square-size-{label}",
                    argv=("lfrefract", "calibrate", command, *views, *board, "--square-size-m", value, *out),
                    says=("--square-size-m",),
                    timeout_s=60,
                )
            )
        cases.append(
            Case(
                group="calibration",
                name=f"camera-square-size-{label}",
                argv=(*cam, *[_air(k) for k in range(5)], *board, "--square-size-m", *[value] * 5, *out),
                says=("--square-size-m",),
                timeout_s=60,
            )
        )
    for squares in (("2", "2"), ("1", "5"), ("0", "0"), ("-3", "5"), ("1000", "1000")):
        for command in ("approx", "port"):
            cases.append(
                Case(
                    group="calibration",
                    name=f"{command}-squares-{'x'.join(squares)}",
                    argv=(
                        "lfrefract",
                        "calibrate",
                        command,
                        *views6,
                        "--squares",
                        *squares,
                        "--square-size-m",
                        port_size,
                        *out,
                    ),
                    says=("--squares",),
                    timeout_s=60,
                )
            )
    for option, values in (
        ("--thickness-m", ("-1", "nan", "inf", "10")),
        ("--n-glass", ("0.5", "nan", "1e300")),
        ("--n-water", ("0.9", "nan", "-1.33")),
    ):
        for value in values:
            cases.append(
                Case(
                    group="calibration",
                    name=f"port{option}={value}",
                    argv=(*port, *views6, *board, "--square-size-m", port_size, option, value, *out),
                    says=(option,),
                    timeout_s=60,
                )
            )
    mla = ("lfrefract", "calibrate", "mla")
    cases += [
        Case(
            group="calibration",
            name="mla-nan-image",
            argv=(*mla, "{C}/cap/raw.exr", "--out", "{C}/o.json"),
            says=("raw.exr",),
            setup=_raw_exr(lambda raw: raw * float("nan")),
        ),
        Case(
            group="calibration",
            name="mla-black-image",
            argv=(*mla, "{C}/cap/raw.exr", "--out", "{C}/o.json"),
            says=("raw.exr",),
            setup=_raw_exr(lambda raw: raw * 0),
        ),
        Case(
            group="calibration",
            name="mla-constant-image",
            argv=(*mla, "{C}/cap/raw.exr", "--out", "{C}/o.json"),
            says=("raw.exr",),
            setup=_raw_exr(lambda raw: raw * 0 + 0.5),
        ),
        Case(
            group="calibration",
            name="mla-reference",
            argv=(*mla, "{F}/white/raw.exr", "--out", "{C}/o.json"),
            expect="ok",
            check=lambda C, s: None if (C / "o.json").exists() else "no output",
        ),
        Case(
            group="calibration",
            name="camera-two-views",
            argv=(*cam, _air(0), _air(1), *board, "--square-size-m", sizes[0], sizes[1], *out),
            says=(("3", "three", "views", "captures"),),
        ),
        Case(
            group="calibration",
            name="camera-sizes-count",
            argv=(*cam, *[_air(k) for k in range(5)], *board, "--square-size-m", sizes[0], sizes[1], *out),
            says=("--square-size-m",),
        ),
        Case(
            group="calibration",
            name="camera-out-is-input",
            argv=(*cam, *[_air(k) for k in range(5)], *board, "--square-size-m", *sizes, "--out", _air(0)),
            says=("raw.exr",),
            inputs=(_air(0),),
        ),
    ]
    return cases


def camera_file_cases() -> list[Case]:
    """``--camera FILE``: the calibrated camera file, edited."""
    cases = []
    raw = "{F}/cap/raw.exr"
    commands = {
        "synth": ("lfrefract", "synth", raw, "--out", "{C}/o.exr", "--quiet", "--camera", "{C}/camera.json"),
        "naive": ("lfrefract", "naive", raw, "--out", "{C}/o.exr", "--camera", "{C}/camera.json"),
        "views": ("lfrefract", "views", raw, "--out", "{C}/views", "--camera", "{C}/camera.json"),
    }

    def edited(edit: Callable[[dict], None] | None) -> Callable[[Path, Path], None]:
        def setup(fixtures: Path, folder: Path) -> None:
            data = _json(fixtures / "camera.json")
            if edit is not None:
                edit(data)
            (folder / "camera.json").write_text(json.dumps(data, allow_nan=True))

        return setup

    def views_ok(folder: Path, stdout: str) -> str | None:
        if not (folder / "views").is_dir():
            return "no views folder"
        return None

    # The unedited calibrated camera: every command runs (on the raw of another camera? no: the
    # fixture capture is the tiny camera and the calibration tiny-2x, so synth must refuse).
    for command, argv in commands.items():
        cases.append(
            Case(
                group="camera-files",
                name=f"{command}-camera-of-another-sensor",
                argv=argv,
                says=(("size", "sensor", "shape", "width"),),
                setup=edited(None),
            )
        )
    board = "{F}/air/b0/raw.exr"
    on_board = {
        "synth": ("lfrefract", "synth", board, "--out", "{C}/o.exr", "--quiet", "--camera", "{C}/camera.json"),
        "naive": ("lfrefract", "naive", board, "--out", "{C}/o.exr", "--camera", "{C}/camera.json"),
        "views": ("lfrefract", "views", board, "--out", "{C}/views", "--camera", "{C}/camera.json"),
    }
    board_port = ("--port", "{F}/port.json")
    for command, argv in on_board.items():
        extra = board_port if command == "synth" else ()
        check = views_ok if command == "views" else _finite_output("o.exr")
        cases.append(
            Case(
                group="camera-files",
                name=f"{command}-calibrated-camera",
                argv=(*argv, *extra),
                expect="ok",
                check=check,
                setup=edited(None),
                timeout_s=600,
            )
        )
        for label, edit in (
            ("covariance-missing", _set("correction_covariance", _DELETE)),
            (
                "covariance-nan",
                lambda d: d["correction_covariance"].__setitem__(
                    "matrix", [[float("nan")] * len(r) for r in d["correction_covariance"]["matrix"]]
                ),
            ),
        ):
            cases.append(
                Case(
                    group="camera-files",
                    name=f"{command}-{label}",
                    argv=(*argv, *extra),
                    expect="either",
                    says=("camera.json", "covariance"),
                    check=check,
                    setup=edited(edit),
                    timeout_s=600,
                )
            )
    synth = (*on_board["synth"], *board_port)
    for label, edit, words in (
        ("kind-edited-to-describe", _set("kind", "lfrefract.describe"), ("kind",)),
        ("kind-edited-to-mla", _set("kind", "lfrefract.calibrate.mla"), ("kind",)),
        ("kind-missing", _set("kind", _DELETE), ("kind",)),
        ("kind-number", _set("kind", 3), ("kind",)),
        ("correction-missing", _set("correction", _DELETE), ("correction",)),
        ("correction-not-a-table", _set("correction", [1, 2]), ("correction",)),
        ("pupil-scale-zero", _set("correction.pupil_scale", 0.0), ("pupil_scale",)),
        ("pupil-scale-nan", _set("correction.pupil_scale", float("nan")), ("pupil_scale",)),
        ("slope-scale-negative", _set("correction.slope_scale", -1.0), ("slope_scale",)),
        ("slope-scale-huge", _set("correction.slope_scale", 1e9), ("slope_scale",)),
        ("k1-string", _set("correction.k1", "x"), ("k1",)),
        ("k1-nan", _set("correction.k1", float("nan")), ("k1",)),
        ("k2-inf", _set("correction.k2", float("inf")), ("k2",)),
        ("unknown-correction-key", _set("correction.k9", 0.1), ("k9",)),
        ("camera-missing", _set("camera", _DELETE), ("camera",)),
        ("camera-focal-nan", _set("camera.focal_length_m", float("nan")), ("focal_length_m",)),
        ("camera-focal-negative", _set("camera.focal_length_m", -0.01), ("focal_length_m",)),
        ("camera-pitch-zero", _set("camera.mla.pitch_m", 0.0), ("pitch_m",)),
        ("camera-width-string", _set("camera.sensor.width_px", "wide"), ("width_px",)),
        (
            "covariance-wrong-shape",
            lambda d: d["correction_covariance"].__setitem__("matrix", [[1.0]]),
            ("covariance",),
        ),
        (
            "covariance-negative-diagonal",
            lambda d: d["correction_covariance"].__setitem__(
                "matrix",
                [
                    [-1.0 if i == j else 0.0 for j in range(len(r))]
                    for i, r in enumerate(d["correction_covariance"]["matrix"])
                ],
            ),
            ("covariance",),
        ),
        ("schema-version-future", _set("schema_version", 999), ("schema",)),
    ):
        cases.append(
            Case(
                group="camera-files",
                name=f"synth-{label}",
                argv=synth,
                says=("camera.json", words if len(words) > 1 else words[0]),
                setup=edited(edit),
            )
        )
    cases += [
        Case(
            group="camera-files",
            name="synth-camera-not-json",
            argv=synth,
            says=("camera.json",),
            setup=lambda F, C: (C / "camera.json").write_text("{oops"),
        ),
        Case(
            group="camera-files",
            name="synth-camera-empty",
            argv=synth,
            says=("camera.json",),
            setup=lambda F, C: (C / "camera.json").write_text(""),
        ),
        Case(
            group="camera-files",
            name="synth-camera-preset-unknown",
            argv=(*on_board["synth"][:-1], "nonesuch", *board_port),
            says=("nonesuch",),
        ),
        Case(
            group="camera-files",
            name="synth-double-gauss-capture-thin-camera",
            argv=("lfrefract", "synth", "{F}/dg/raw.exr", "--out", "{C}/o.exr", "--quiet"),
            expect="either",
            says=(("lens", "double-gauss"),),
            check=lambda C, out: None if "double" in out.lower() else "no word of the capture's lens",
        ),
    ]
    return cases


def synthesis_cases() -> list[Case]:
    """Options of ``synth``, ``naive`` and ``views``; raw images out of range."""
    raw = "{F}/cap/raw.exr"
    synth = ("lfrefract", "synth", raw, "--out", "{C}/o.exr", "--quiet")
    cases = []
    bad = {
        "--k": ("0", "-1", "1000000000", "nan", "2.5"),
        "--supersample": ("0", "-1", "100000", "nan"),
        "--lambda": ("-1", "nan", "inf"),
    }
    for option, values in bad.items():
        for value in values:
            cases.append(
                Case(group="synthesis", name=f"synth{option}={value}", argv=(*synth, option, value), says=(option,))
            )
    da = (*synth, "--method", "depth-aware")
    for label, values in (
        ("tiny", ("1e-9", "1e-8")),
        ("reversed", ("2", "1")),
        ("negative", ("-1", "1")),
        ("nan", ("nan", "1")),
        ("equal", ("1", "1")),
        ("zero", ("0", "1")),
        ("inf", ("0.1", "inf")),
    ):
        cases.append(
            Case(
                group="synthesis",
                name=f"depth-range-{label}",
                argv=(*da, "--depth-range", *values),
                says=("--depth-range",),
                timeout_s=600,
            )
        )
    # A range that leaves out the scene is a choice the data cannot contradict: its result must still be
    # an image, with the depths it searched.
    cases.append(
        Case(
            group="synthesis",
            name="depth-range-far-beyond-the-scene",
            argv=(*da, "--depth-range", "1e3", "1e4", "--depth-steps", "8"),
            expect="either",
            says=("--depth-range",),
            check=_finite_output("o.exr"),
            timeout_s=600,
        )
    )
    for option, values in (("--depth-steps", ("0", "2", "-5", "100000000")), ("--aggregation-radius", ("-1", "nan"))):
        for value in values:
            cases.append(
                Case(group="synthesis", name=f"depth-aware{option}={value}", argv=(*da, option, value), says=(option,))
            )
    cases.append(
        Case(
            group="synthesis",
            name="depth-range-option-without-depth-aware",
            argv=(*synth, "--depth-range", "0.2", "1"),
            says=("--depth-range",),
        )
    )
    # Raw images out of range.
    for label, make, words in (
        ("huge-finite", lambda r: r * 0 + 3e38, ("raw.exr",)),
        ("all-nan", lambda r: r * float("nan"), ("raw.exr",)),
        ("negative", lambda r: r - 1e3, ("raw.exr",)),
        ("one-inf", lambda r: _poke(r, float("inf")), ("raw.exr",)),
    ):
        for command in ("synth", "naive"):
            cases.append(
                Case(
                    group="synthesis",
                    name=f"{command}-raw-{label}",
                    argv=("lfrefract", command, "{C}/cap/raw.exr", "--out", "{C}/o.exr"),
                    says=words,
                    setup=_raw_exr(make),
                    inputs=("{C}/cap/raw.exr",),
                )
            )
    cases.append(
        Case(
            group="synthesis",
            name="synth-raw-huge-finite-mask",
            argv=("lfrefract", "synth", "{C}/cap/raw.exr", "--out", "{C}/o.exr", "--nonfinite", "mask"),
            says=("raw.exr",),
            setup=_raw_exr(lambda r: r * 0 + 3e38),
        )
    )
    cases.append(
        Case(
            group="synthesis",
            name="synth-raw-wrong-size",
            argv=("lfrefract", "synth", "{C}/cap/raw.exr", "--out", "{C}/o.exr"),
            says=("raw.exr",),
            setup=_raw_exr(lambda r: r[:-4]),
        )
    )
    cases.append(
        Case(
            group="synthesis",
            name="synth-raw-one-channel",
            argv=("lfrefract", "synth", "{C}/cap/raw.exr", "--out", "{C}/o.exr"),
            expect="either",
            says=("raw.exr",),
            check=_finite_output("o.exr"),
            setup=_raw_exr(lambda r: r[..., 0]),
        )
    )
    # Ports: impossible geometry.
    for label, port in (
        ("normal-backwards", "[port]\nnormal = [0, 0, -1]\ndistance_m = 0.02\nthickness_m = 0.005\n"),
        ("distance-negative", "[port]\ntilt_x_deg = 10\ndistance_m = -0.02\nthickness_m = 0.005\n"),
        ("distance-nan", "[port]\ntilt_x_deg = 10\ndistance_m = nan\nthickness_m = 0.005\n"),
        ("tilt-90", "[port]\ntilt_x_deg = 90\ndistance_m = 0.02\nthickness_m = 0.005\n"),
        ("n-water-below-1", "[port]\ntilt_x_deg = 10\ndistance_m = 0.02\nthickness_m = 0.005\nn_water = 0.5\n"),
        ("unknown-key", "[port]\ntilt_x_deg = 10\ndistance_m = 0.02\nthickness_m = 0.005\ncolour = 'blue'\n"),
        ("normal-zero", "[port]\nnormal = [0, 0, 0]\ndistance_m = 0.02\nthickness_m = 0.005\n"),
        ("not-toml", "[port\n"),
    ):
        cases.append(
            Case(
                group="synthesis",
                name=f"port-{label}",
                argv=(*synth, "--port", "{C}/port.toml"),
                says=("port.toml",),
                setup=lambda F, C, text=port: (C / "port.toml").write_text(text),
            )
        )
    cases += [
        Case(
            group="synthesis",
            name="map-cache-is-a-file",
            argv=(*synth, "--map-cache", "{C}/cache"),
            says=("cache",),
            setup=lambda F, C: (C / "cache").write_text("x"),
        ),
        Case(
            group="synthesis",
            name="views-grid-zero",
            argv=("lfrefract", "views", raw, "--out", "{C}/v", "--grid", "0"),
            says=("--grid",),
        ),
        Case(
            group="synthesis",
            name="reference-synth",
            argv=synth,
            expect="ok",
            check=_finite_output("o.exr"),
            inputs=(raw,),
        ),
        Case(
            group="synthesis",
            name="reference-depth-aware",
            argv=(*da, "--depth-steps", "8"),
            expect="ok",
            check=_finite_output("o.exr"),
            timeout_s=600,
        ),
    ]
    return cases


def _poke(raw, value):
    raw = raw.copy()
    raw[raw.shape[0] // 2, raw.shape[1] // 2, 0] = value
    return raw


def output_cases() -> list[Case]:
    """Where outputs go: the inputs, read-only folders, a full disk, names of other kinds."""
    raw = "{F}/cap/raw.exr"
    cases = []
    writers = {
        "synth": ("lfrefract", "synth", raw, "--quiet", "--out"),
        "naive": ("lfrefract", "naive", raw, "--out"),
        "render": ("lfsim", "render", "--spp", "1", "--quiet", "--no-previews", "--out"),
    }
    suffix = {"synth": ".exr", "naive": ".exr", "render": ""}
    for command, argv in writers.items():
        s = suffix[command]
        cases += [
            Case(
                group="outputs",
                name=f"{command}-read-only-folder",
                argv=(*argv, "{C}/ro/o" + s),
                says=("ro",),
                setup=_read_only_folder,
            ),
            Case(
                group="outputs",
                name=f"{command}-full-disk",
                argv=(*argv, "{C}/full/o" + s),
                says=("full",),
                setup=_full_disk_folder,
            ),
            Case(
                group="outputs",
                name=f"{command}-out-is-a-file-of-another-kind",
                argv=(*argv, "{C}/keep" + s, "--overwrite"),
                says=("keep",),
                setup=lambda F, C, s=s: (C / ("keep" + s)).write_text("precious"),
                after=lambda F, C, r, s=s: (
                    None
                    if (C / ("keep" + s)).is_file() and (C / ("keep" + s)).read_text() == "precious"
                    else "overwrote a file of another kind"
                ),
            ),
        ]
    cases += [
        Case(
            group="outputs",
            name="synth-out-is-the-input",
            argv=("lfrefract", "synth", "{C}/cap/raw.exr", "--out", "{C}/cap/raw.exr", "--overwrite"),
            says=("raw.exr",),
            setup=_raw_exr(lambda r: r),
            inputs=("{C}/cap/raw.exr",),
        ),
        Case(
            group="outputs",
            name="synth-out-is-the-meta-json",
            argv=("lfrefract", "synth", "{C}/cap/raw.exr", "--out", "{C}/cap/meta.json", "--overwrite"),
            says=("meta.json",),
            setup=_raw_exr(lambda r: r),
            inputs=("{C}/cap/meta.json",),
        ),
        # A folder holding a capture that no lfsim command wrote (no manifest): never replaced.
        Case(
            group="outputs",
            name="render-over-a-folder-of-another-writer",
            argv=("lfsim", "render", "--spp", "1", "--quiet", "--out", "{C}/cap", "--overwrite"),
            says=("cap",),
            setup=_raw_exr(lambda r: r),
            inputs=("{C}/cap/raw.exr", "{C}/cap/meta.json"),
        ),
        Case(
            group="outputs",
            name="synth-out-exists",
            argv=("lfrefract", "synth", raw, "--quiet", "--out", "{C}/o.exr"),
            says=("o.exr", "--overwrite"),
            setup=lambda F, C: (C / "o.exr").write_text("x"),
        ),
        Case(
            group="outputs",
            name="synth-out-parent-is-a-file",
            argv=("lfrefract", "synth", raw, "--quiet", "--out", "{C}/f/o.exr"),
            says=("f",),
            setup=lambda F, C: (C / "f").write_text("x"),
        ),
        Case(
            group="outputs",
            name="synth-out-wrong-suffix",
            argv=("lfrefract", "synth", raw, "--quiet", "--out", "{C}/o.png"),
            says=("o.png",),
        ),
        Case(
            group="outputs",
            name="calibrate-mla-full-disk",
            argv=("lfrefract", "calibrate", "mla", "{F}/white/raw.exr", "--out", "{C}/full/mla.json"),
            says=("full",),
            setup=_full_disk_folder,
        ),
    ]
    return cases


def _read_only_folder(fixtures: Path, folder: Path) -> None:
    """``ro``: a folder nobody may write into; for root (who ignores modes) an immutable one."""
    (folder / "ro").mkdir()
    os.chmod(folder / "ro", 0o555)
    if os.geteuid() == 0:
        subprocess.run(["chattr", "+i", str(folder / "ro")], check=True)


def _full_disk_folder(fixtures: Path, folder: Path) -> None:
    """``full``: a folder whose every write fails as on a full disk (a 1 MiB file-size limit is
    not it: the command runs under RLIMIT_FSIZE set by ``full_disk`` in :func:`run_case`)."""
    (folder / "full").mkdir()
    (folder / "FULL_DISK").write_text("")


def simulator_cases() -> list[Case]:
    """``lfsim``: scene files, options and the experiments' kept renders."""
    cases = []
    scene_base = (
        '[camera]\npreset = "tiny"\n[port]\ndistance_m = 0.02\nthickness_m = 0.004\ntilt_x_deg = 10.0\n'
        '[render]\nspp = 1\n[[light]]\ntype = "point"\nposition_m = [0.0, -0.2, 0.1]\nintensity_w_sr = 0.3\n'
        '[[object]]\ntype = "textured_plane"\nposition_m = [0.0, 0.0, 0.6]\nsize_m = [0.8, 0.6]\ntexture_px = 64\n'
    )
    edits = {
        "tilt-90": ("tilt_x_deg = 10.0", "tilt_x_deg = 90.0"),
        "tilt-nan": ("tilt_x_deg = 10.0", "tilt_x_deg = nan"),
        "distance-negative": ("distance_m = 0.02", "distance_m = -0.02"),
        "thickness-negative": ("thickness_m = 0.004", "thickness_m = -0.004"),
        "spp-zero": ("spp = 1", "spp = 0"),
        "spp-string": ("spp = 1", 'spp = "many"'),
        "preset-unknown": ('preset = "tiny"', 'preset = "hasselblad"'),
        "lens-unknown": ('preset = "tiny"', 'preset = "tiny"\nlens = "fisheye-9000"'),
        "plane-behind-port": ("position_m = [0.0, 0.0, 0.6]", "position_m = [0.0, 0.0, 0.01]"),
        "plane-size-zero": ("size_m = [0.8, 0.6]", "size_m = [0.0, 0.6]"),
        "light-intensity-nan": ("intensity_w_sr = 0.3", "intensity_w_sr = nan"),
        "object-type-unknown": ('type = "textured_plane"', 'type = "teapot"'),
        "unknown-table": ("[render]", "[rendr]"),
        "unknown-key": ("spp = 1", "spp = 1\nsamples = 4"),
        "texture-huge": ("texture_px = 64", "texture_px = 10000000"),
        "mesh-missing": (
            "texture_px = 64\n",
            'texture_px = 64\n[[object]]\ntype = "mesh"\npath = "none.obj"\nposition_m = [0.0, 0.0, 0.4]\n',
        ),
        "not-toml": ("[camera]", "[camera"),
    }
    for label, (old, new) in edits.items():
        text = scene_base.replace(old, new)
        word = {
            "not-toml": "scene.toml",
            "mesh-missing": "none.obj",
            "unknown-table": "rendr",
            "unknown-key": "samples",
            "preset-unknown": "hasselblad",
            "lens-unknown": "fisheye-9000",
            "object-type-unknown": "teapot",
        }.get(label, "scene.toml")
        cases.append(
            Case(
                group="simulator",
                name=f"scene-{label}",
                argv=("lfsim", "render", "{C}/scene.toml", "--out", "{C}/r", "--quiet", "--no-previews"),
                says=(word,),
                setup=lambda F, C, t=text: (C / "scene.toml").write_text(t),
                timeout_s=300,
            )
        )
    for option, value in (
        ("--spp", "0"),
        ("--spp", "-1"),
        ("--seed", "-1"),
        ("--ideal-spp", "0"),
        ("--band-pixels", "0"),
        ("--frames", "0"),
    ):
        cases.append(
            Case(
                group="simulator",
                name=f"render{option}={value}",
                argv=("lfsim", "render", "--out", "{C}/r", "--quiet", option, value),
                says=(option,),
            )
        )
    for option, value in (
        ("--frames", "0"),
        ("--spp", "0"),
        ("--focus-m", "-1"),
        ("--focus-m", "abc"),
        ("--focal-lengths-mm", "0"),
        ("--focal-lengths-mm", "nan"),
    ):
        cases.append(
            Case(
                group="simulator",
                name=f"whites{option}={value}",
                argv=("lfsim", "whites", "--camera", "tiny", "--out", "{C}/w", "--quiet", option, value),
                says=(option,),
            )
        )
    for option, value in (
        ("--tilts-deg", "95"),
        ("--tilts-deg", "nan"),
        ("--f-numbers", "0"),
        ("--port-distance-m", "-1"),
        ("--thickness-m", "nan"),
        ("--methods", "nonesuch"),
    ):
        cases.append(
            Case(
                group="simulator",
                name=f"experiment-fov{option}={value}",
                argv=("lfsim", "experiment", "fov", "--out", "{C}/e", "--quiet", f"{option}={value}"),
                says=(option if option != "--methods" else "nonesuch",),
            )
        )
    cases.append(
        Case(
            group="simulator",
            name="experiment-renders-inside-out",
            argv=("lfsim", "experiment", "planes", "--out", "{C}/e", "--renders", "{C}/e/r", "--quiet"),
            says=("--renders",),
        )
    )
    cases.append(
        Case(
            group="simulator",
            name="renders-tampered-raw",
            argv=(
                "lfsim",
                "experiment",
                "planes",
                "--out",
                "{C}/e2",
                "--renders",
                "{C}/r",
                "--quiet",
                "--methods",
                "proposed",
            ),
            expect="either",
            says=("raw",),
            setup=_tampered_renders,
            check=_same_table_as_untampered,
            timeout_s=1800,
        )
    )
    return cases


def _tampered_renders(fixtures: Path, folder: Path) -> None:
    """A planes experiment run once with kept renders (``r``, ``e1``), one capture's raw image then
    replaced by another's (same size)."""
    env = _environment(Path(os.environ["AUDIT_TREE"]))
    argv = [
        sys.executable,
        "-m",
        "simulator.cli",
        "experiment",
        "planes",
        "--out",
        str(folder / "e1"),
        "--renders",
        str(folder / "r"),
        "--quiet",
        "--methods",
        "proposed",
    ]
    _run(argv, env=env, cwd=folder, timeout=1800)
    raws = sorted((folder / "r").rglob("raw.exr"))
    if len(raws) < 2:
        raise SystemExit(f"planes kept {len(raws)} raw images in {folder / 'r'}")
    shutil.copy(raws[-1], raws[0])


def _same_table_as_untampered(folder: Path, stdout: str) -> str | None:
    first, second = folder / "e1" / "table.csv", folder / "e2" / "table.csv"
    if not second.exists():
        return "no table"
    return None if first.read_text() == second.read_text() else "the table differs from the untampered run's"


def signal_cases() -> list[Case]:
    """SIGINT and SIGTERM mid-run; a later run resumes."""
    tilts = ", ".join(f"{2.0 * k:.1f}" for k in range(12))
    spec = f'[sweep]\nname = "tilt"\nseed = 5\nscene = "default"\n[grid]\n"port.tilt_x_deg" = [{tilts}]\n'
    cases = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        name = signal.Signals(signum).name
        cases += [
            Case(
                group="signals",
                name=f"dataset-run-{name}",
                argv=("lfsim", "dataset", "run", "{C}/spec.toml", "--out", "{C}/ds", "--workers", "1"),
                expect="interrupt",
                signal_after_s=12.0,
                signum=signum,
                setup=lambda F, C: (C / "spec.toml").write_text(spec),
            ),
            Case(
                group="signals",
                name=f"render-{name}",
                argv=("lfsim", "render", "--out", "{C}/r", "--quiet", "--spp", "64"),
                expect="interrupt",
                signal_after_s=8.0,
                signum=signum,
            ),
            Case(
                group="signals",
                name=f"synth-{name}",
                argv=(
                    "lfrefract",
                    "synth",
                    "{F}/cap/raw.exr",
                    "--out",
                    "{C}/o.exr",
                    "--quiet",
                    "--method",
                    "depth-aware",
                ),
                expect="interrupt",
                signal_after_s=4.0,
                signum=signum,
            ),
            Case(
                group="signals",
                name=f"views-calibrated-camera-{name}",
                argv=("lfrefract", "views", "{F}/air/b0/raw.exr", "--out", "{C}/v", "--camera", "{F}/camera.json"),
                expect="interrupt",
                signal_after_s=1.5,
                signum=signum,
            ),
        ]
    return cases


def held_out_cases() -> list[Case]:
    """Cases written after the fixes of the first audit (2026-12-07), none of them used while fixing:
    whether those fixes generalise to inputs of the same families that nobody tried."""
    raw = "{F}/cap/raw.exr"
    tiny_camera = (
        'schema_version = 1\n[camera]\nname = "mine"\nfocal_length_m = 0.01\nlens_to_mla_m = 0.01\nf_number = 4.0\n'
        '[camera.mla]\ngrid = "hex"\npitch_m = 5e-05\nfocal_length_m = 0.0002\nrotation_rad = 0.0\n'
        "offset_m = [0.0, 0.0]\n[camera.sensor]\nwidth_px = 480\nheight_px = 360\npixel_pitch_m = 5e-06\n"
    )
    port = "schema_version = 1\n[port]\ndistance_m = 0.02\nthickness_m = 0.004\ntilt_x_deg = 10.0\n"

    def write(name: str, text: str) -> Callable[[Path, Path], None]:
        return lambda F, C: (C / name).write_text(text)

    def copy(source: str, name: str) -> Callable[[Path, Path], None]:
        return lambda F, C: shutil.copy(_fmt(source, F, C), C / name)

    synth = ("lfrefract", "synth", raw, "--out", "{C}/o.exr", "--quiet")
    cases = [
        (
            "camera-toml-nan-focal",
            (*synth, "--camera", "{C}/cam.toml"),
            ("cam.toml", "focal_length_m"),
            write("cam.toml", tiny_camera.replace("focal_length_m = 0.01", "focal_length_m = nan")),
        ),
        (
            "camera-toml-unknown-key",
            (*synth, "--camera", "{C}/cam.toml"),
            ("cam.toml", "colour"),
            write("cam.toml", tiny_camera.replace("f_number = 4.0", "f_number = 4.0\ncolour = 'red'")),
        ),
        (
            "camera-toml-other-sensor",
            (*synth, "--camera", "{C}/cam.toml"),
            (("480", "size", "sensor"),),
            write("cam.toml", tiny_camera.replace("width_px = 480", "width_px = 640")),
        ),
        (
            "port-normal-not-unit",
            (*synth, "--port", "{C}/p.toml"),
            ("p.toml", "normal"),
            write("p.toml", port.replace("tilt_x_deg = 10.0", "normal = [0.0, 0.0, 2.0]")),
        ),
        (
            "port-tilt-and-normal",
            (*synth, "--port", "{C}/p.toml"),
            ("p.toml",),
            write("p.toml", port + "normal = [0.0, 0.0, 1.0]\n"),
        ),
        (
            "port-json-kind-camera",
            (*synth, "--port", "{C}/p.json"),
            ("p.json", "kind"),
            write(
                "p.json",
                json.dumps(
                    {
                        "schema_version": 1,
                        "kind": "lfrefract.camera",
                        "port": {"distance_m": 0.02, "thickness_m": 0.004, "tilt_x_deg": 10.0},
                    }
                ),
            ),
        ),
        (
            "ideal-given-as-raw",
            ("lfrefract", "naive", "{C}/ideal.exr", "--out", "{C}/o.exr", "--camera", "tiny"),
            ("ideal.exr", ("role", "ideal")),
            copy("{F}/cap/ideal.exr", "ideal.exr"),
        ),
        (
            "depth-given-as-raw",
            ("lfrefract", "synth", "{C}/depth.exr", "--out", "{C}/o.exr", "--camera", "tiny", "--port", "{C}/p.toml"),
            ("depth.exr",),
            _combined(copy("{F}/cap/depth.exr", "depth.exr"), write("p.toml", port)),
        ),
        ("describe-missing-file", ("lfrefract", "describe", "{C}/none.json"), ("none.json",), None),
        ("describe-empty-json", ("lfrefract", "describe", "{C}/e.json"), ("e.json",), write("e.json", "{}")),
        (
            "synth-of-a-synth-output",
            ("lfrefract", "naive", "{C}/rf.exr", "--out", "{C}/o.exr", "--camera", "tiny"),
            ("rf.exr",),
            None,
        ),
        (
            "calibrate-approx-two-cameras",
            (
                "lfrefract",
                "calibrate",
                "approx",
                _port(0),
                _port(1),
                "{F}/cap/raw.exr",
                "--squares",
                *SQUARES,
                "--square-size-m",
                "0.01",
                "--out",
                "{C}/a.json",
            ),
            (("camera", "size"),),
            None,
        ),
        (
            "white-folder-of-another-sensor-only",
            ("lfrefract", "naive", "{F}/lfr/capture.lfr", "--out", "{C}/o.exr", "--white", "{C}/w"),
            ("w",),
            None,
        ),
        (
            "mla-out-over-its-white",
            ("lfrefract", "calibrate", "mla", "{C}/white/raw.exr", "--out", "{C}/white/meta.json", "--overwrite"),
            ("meta.json",),
            None,
        ),
        (
            "render-spp-huge",
            ("lfsim", "render", "--out", "{C}/r", "--quiet", "--spp", "1000000000000"),
            ("--spp",),
            None,
        ),
        ("whites-camera-unknown", ("lfsim", "whites", "--camera", "nonesuch", "--out", "{C}/w"), ("nonesuch",), None),
    ]

    def synth_output(fixtures: Path, folder: Path) -> None:
        env = _environment(Path(os.environ.get("AUDIT_TREE", str(REPO))))
        argv = [
            sys.executable,
            "-m",
            "lfrefract",
            "synth",
            str(fixtures / "cap" / "raw.exr"),
            "--out",
            str(folder / "rf.exr"),
            "--quiet",
        ]
        _run(argv, env=env, cwd=folder)

    def other_sensor_whites(fixtures: Path, folder: Path) -> None:
        sys.path.insert(0, os.environ.get("AUDIT_TREE", str(REPO)))
        import numpy as np

        from lfrefract.formats.lytro import pack_10bit

        (folder / "w").mkdir()
        raw = _whites_index(fixtures)[0]
        meta = next(p for p in (raw.with_suffix(".txt"), raw.with_suffix(".json")) if p.exists())
        data = _json(meta)
        data["image"]["width"] -= 8
        for key in ("pixelWidth",):
            if key in data.get("devices", {}).get("sensor", {}):
                data["devices"]["sensor"][key] -= 8
        (folder / "w" / ("w" + meta.suffix)).write_text(json.dumps(data))
        h, w = data["image"]["height"], data["image"]["width"]
        (folder / "w" / "w.raw").write_bytes(pack_10bit(np.full((h, w), 300, np.uint16)))

    def white_render(fixtures: Path, folder: Path) -> None:
        shutil.copytree(fixtures / "white", folder / "white")

    extra_setup = {
        "synth-of-a-synth-output": synth_output,
        "white-folder-of-another-sensor-only": other_sensor_whites,
        "mla-out-over-its-white": white_render,
    }
    # A port file's normal is a direction (docs/cli.md: "scaled to unit length"; distance_m is the
    # distance along it): this case first expected a refusal, which the documented contract does not ask.
    either = {"port-normal-not-unit"}
    out = []
    for name, argv, says, setup in cases:
        out.append(
            Case(
                group="held-out",
                name=name,
                argv=argv,
                says=says,
                expect="either" if name in either else "refuse",
                check=_finite_output("o.exr") if name in either else None,
                setup=extra_setup.get(name, setup),
                inputs=("{C}/white/meta.json",) if name == "mla-out-over-its-white" else (),
            )
        )
    return out


def all_cases(fixtures: Path) -> list[Case]:
    cases = [
        *lytro_cases(),
        *white_cases(),
        *calibration_cases(fixtures),
        *camera_file_cases(),
        *synthesis_cases(),
        *output_cases(),
        *simulator_cases(),
        *signal_cases(),
        *held_out_cases(),
    ]
    names = collections.Counter((c.group, c.name) for c in cases)
    repeated = [n for n, count in names.items() if count > 1]
    if repeated:
        raise SystemExit(f"case names repeated: {repeated}")
    return cases


# =============================================================================== running
def _environment(tree: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    env["PYTHONPATH"] = str(tree)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env.setdefault("OMP_NUM_THREADS", "1")
    return env


def _digest(path: Path) -> str | None:
    if not path.exists():
        return None
    if path.is_dir():
        return "dir"
    return hashlib.blake2b(path.read_bytes(), digest_size=16).hexdigest()


def _limits(memory_bytes: int | None, full_disk: bool) -> Callable[[], None]:
    def apply() -> None:
        os.setsid()
        if memory_bytes is not None:
            resource.setrlimit(resource.RLIMIT_AS, (memory_bytes, memory_bytes))
        if full_disk:
            # Writes past 1 KiB fail with EFBIG, as they would with ENOSPC on a full disk.
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
            resource.setrlimit(resource.RLIMIT_FSIZE, (1024, 1024))

    return apply


def _words_present(message: str, says: tuple) -> list[str]:
    """The words of ``says`` (a tuple in it: any one of them) missing from ``message``."""
    text = message.lower()
    missing = []
    for word in says:
        options = word if isinstance(word, tuple) else (word,)
        if not any(str(o).lower() in text for o in options):
            missing.append("/".join(map(str, options)))
    return missing


def run_case(case: Case, *, fixtures: Path, root: Path, tree: Path, memory_gb: float) -> dict:
    folder = root / f"{case.group}-{case.name}".replace("/", "_")
    if folder.exists():
        if os.geteuid() == 0 and (folder / "ro").exists():
            subprocess.run(["chattr", "-i", str(folder / "ro")], check=False)
        for path in folder.rglob("*"):
            if path.is_dir():
                os.chmod(path, 0o755)
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    started = time.monotonic()
    record: dict = {"group": case.group, "name": case.name}
    try:
        if case.setup is not None:
            case.setup(fixtures, folder)
    except (SystemExit, Exception) as exc:  # the case's own set-up, not the command audited
        return {**record, "class": "setup-failed", "detail": f"{type(exc).__name__}: {exc}"[-500:]}
    inputs = [Path(_fmt(p, fixtures, folder)) for p in case.inputs]
    before = {p: _digest(p) for p in inputs}
    # As the scripts start them (python -m simulator where the tree has it: older trees ran simulator.cli).
    lfsim = "simulator" if (tree / "simulator" / "__main__.py").exists() else "simulator.cli"
    module = {"lfrefract": "lfrefract", "lfsim": lfsim}[case.argv[0]]
    argv = [sys.executable, "-m", module, *(_fmt(a, fixtures, folder) for a in case.argv[1:])]
    # Dr.Jit's LLVM backend reserves address space: the memory limit is for the core's commands.
    memory = int(memory_gb * 2**30) if case.argv[0] == "lfrefract" else None
    full_disk = (folder / "FULL_DISK").exists()
    env = _environment(tree)
    proc = subprocess.Popen(
        argv,
        env=env,
        cwd=folder,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_limits(memory, full_disk),
    )
    timed_out = False
    signal_sent = None
    try:
        if case.signal_after_s is not None:
            try:
                proc.wait(timeout=case.signal_after_s)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, case.signum)  # as a terminal's Ctrl-C: the whole process group
                signal_sent = time.monotonic()
        stdout, stderr = proc.communicate(timeout=case.timeout_s)
    except subprocess.TimeoutExpired:
        timed_out = True
        os.killpg(proc.pid, signal.SIGKILL)
        stdout, stderr = proc.communicate()
    ended = time.monotonic()
    rc = proc.returncode
    record.update(rc=rc, seconds=round(ended - started, 1), stderr=stderr[-1500:], stdout=stdout[-800:])
    lines = [line for line in stderr.strip().splitlines() if line.strip()]
    traceback = "Traceback (most recent call last)" in stderr

    def verdict(cls: str, detail: str = "") -> dict:
        return {**record, "class": cls, "detail": detail}

    changed = [str(p) for p, d in before.items() if _digest(p) != d]
    if timed_out:
        return verdict("crash", f"timed out after {case.timeout_s} s")
    if case.expect == "interrupt" and rc == -case.signum and not traceback:
        rc = 128 + case.signum  # ended by the signal's default action (before a handler was set): no traceback
    if traceback or rc < 0 or rc not in (0, 2, 130, 143):
        return verdict("crash", f"exit {rc}" + (" with a traceback" if traceback else ""))
    if changed:
        return verdict("silent", f"input changed: {changed}")
    if case.expect == "interrupt":
        if signal_sent is None:
            return verdict("ok", f"ended before the signal (exit {rc})") if rc == 0 else verdict("ok", "")
        if rc != 128 + case.signum:
            return verdict("crash", f"exit {rc} after {case.signum}")
        if ended - signal_sent > 10:
            return verdict("crash", f"ended {ended - signal_sent:.0f} s after the signal")
        leftovers = [p.name for p in folder.rglob("*") if ".tmp" in p.name or p.name.startswith(".staging")]
        if leftovers:
            return verdict("silent", f"left half-written: {leftovers[:3]}")
        return verdict("ok")
    problem = None
    if case.after is not None:
        problem = case.after(fixtures, folder, record)
    if problem:
        return verdict("silent", problem)
    if rc == 2:
        if case.expect == "ok":
            return verdict("refused", lines[-1] if lines else "")
        missing = _words_present(stderr, case.says)
        error_lines = [line for line in lines if ": error:" in line or line.startswith("usage:")]
        if missing:
            return verdict("unclear", f"does not name {missing}: {lines[-1] if lines else ''}")
        if not error_lines:
            return verdict("unclear", f"no error line: {lines[-1] if lines else ''}")
        return verdict("ok", lines[-1])
    if rc in (130, 143):
        return verdict("crash", f"exit {rc} without a signal")
    # rc == 0
    if case.expect == "refuse":
        return verdict("silent", "exit 0 where a refusal was due")
    if case.check is not None:
        problem = case.check(folder, stdout + stderr)
        if problem:
            return verdict("silent", problem)
    return verdict("ok")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--work", type=Path, required=True, help="folder for the fixtures and the cases")
    parser.add_argument("--tree", type=Path, default=REPO, help="source tree audited (default: this one)")
    parser.add_argument("--jobs", type=int, default=2, help="cases run at once")
    parser.add_argument("--only", default="", help="groups or case-name parts, separated by commas")
    parser.add_argument("--memory-gb", type=float, default=6.0, help="address space of each core command")
    parser.add_argument("--json", type=Path, help="write every case's outcome here")
    parser.add_argument("--list", action="store_true", help="list the cases and stop")
    parser.add_argument("--again", action="store_true", help="run the chosen cases again (their outcomes forgotten)")
    args = parser.parse_args(argv)
    fixtures = args.work / "fixtures"
    if not args.list:
        claim_work_folder(args.work)
        build_fixtures(fixtures, args.tree.resolve())
    cases = all_cases(fixtures)
    if args.only:
        parts = [p for p in args.only.split(",") if p]
        cases = [c for c in cases if any(p == c.group or p in c.name for p in parts)]
    if args.list:
        for case in cases:
            print(f"{case.group:16s} {case.name}")
        print(f"{len(cases)} cases")
        return 0
    tree = args.tree.resolve()
    os.environ["AUDIT_TREE"] = str(tree)
    root = args.work / ("cases-" + hashlib.blake2b(str(tree).encode(), digest_size=4).hexdigest())
    # References first (other cases compare with them), the long ones next.
    cases.sort(key=lambda c: ("reference" not in c.name, -c.timeout_s))
    # Each outcome is appended to outcomes.jsonl as it comes: a run stopped half-way resumes with
    # the cases it has not done (--again runs every case again).
    log = root / "outcomes.jsonl"
    root.mkdir(parents=True, exist_ok=True)
    wanted = {(c.group, c.name) for c in cases}
    done = {}
    if log.exists():
        for line in log.read_text().splitlines():
            record = json.loads(line)
            done[(record["group"], record["name"])] = record
    if args.again:  # the chosen cases' outcomes are forgotten, the others' kept
        done = {key: r for key, r in done.items() if key not in wanted}
        log.write_text("".join(json.dumps(r) + "\n" for r in done.values()))
    results = [r for key, r in done.items() if key in wanted]
    todo = [c for c in cases if (c.group, c.name) not in done]
    started = time.monotonic()
    print(f"{len(cases)} cases on {tree} ({len(todo)} to run)", flush=True)

    def submit_all(pool, chosen):
        return [
            pool.submit(run_case, c, fixtures=fixtures, root=root, tree=tree, memory_gb=args.memory_gb) for c in chosen
        ]

    with concurrent.futures.ThreadPoolExecutor(args.jobs) as pool, log.open("a") as sink:
        for batch in ([c for c in todo if "reference" in c.name], [c for c in todo if "reference" not in c.name]):
            for future in concurrent.futures.as_completed(submit_all(pool, batch)):
                result = future.result()
                results.append(result)
                sink.write(json.dumps(result) + "\n")
                sink.flush()
                if result["class"] != "ok":
                    print(
                        f"{result['class']:8s} {result['group']}/{result['name']}: {result['detail'][:300]}", flush=True
                    )
    counts: dict = collections.defaultdict(collections.Counter)
    for r in results:
        counts[r["group"]][r["class"]] += 1
    classes = ["ok", "crash", "silent", "unclear", "refused", "setup-failed"]
    print(f"\n{'group':16s} " + " ".join(f"{c:>8s}" for c in classes) + "   total")
    total: collections.Counter = collections.Counter()
    for group in sorted(counts):
        total.update(counts[group])
        print(
            f"{group:16s} " + " ".join(f"{counts[group][c]:8d}" for c in classes) + f"   {sum(counts[group].values())}"
        )
    print(f"{'all':16s} " + " ".join(f"{total[c]:8d}" for c in classes) + f"   {sum(total.values())}")
    print(f"{time.monotonic() - started:.0f} s, tree {tree}")
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
