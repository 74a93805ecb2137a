"""Where commands write, and what ``--overwrite`` may replace: the project's data-safety rules.

Every file the project writes goes through :func:`atomic_file` (a unique temporary name beside
the destination, renamed into place when complete, removed on failure). Every output directory
goes through :func:`staged_directory`: it is assembled in a hidden staging directory beside its
destination and renamed into place only when complete, and it ends with a manifest,
``.lfrefract-output.json``, naming its kind and every file and folder in it with its size.

The rules (``docs/conventions.md``, "Outputs and --overwrite"):

* a command refuses an existing output unless told to overwrite it;
* ``overwrite`` replaces a directory only if its manifest says it is an output of the same kind
  and it holds nothing but the files the manifest lists, each of the size it was written with
  (a file added, a file edited, a folder of anything else: refused, with the path in the way);
* ``overwrite`` replaces a single file only if it is the same kind of output (the role in an
  EXR header, the ``kind`` of a JSON sidecar, or a companion listed in such a sidecar);
* no command writes over one of its inputs, nor replaces a directory that holds one, nor uses
  the current directory (or one of its parents) as an output directory;
* staging directories left by a killed process (no live process holds their lock) are removed
  by the next output into the same parent; an earlier output moved aside for replacement is put
  back if the new one never took its place; SIGTERM and Ctrl-C are turned into a clean exit by the CLIs
  (:func:`terminate_cleanly`), which also removes the scratch folders of :func:`scratch_directory`
  (the temporary working folders of the simulator's experiments).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "MANIFEST_NAME",
    "ExpectedKind",
    "atomic_file",
    "current_umask",
    "on_termination",
    "output_manifest",
    "prepare_output_files",
    "refuse_own_inputs",
    "remove_stale_staging",
    "scratch_directory",
    "staged_directory",
    "terminate_cleanly",
]

#: Name of the manifest that :func:`staged_directory` writes into every output directory.
MANIFEST_NAME = ".lfrefract-output.json"

_MANIFEST_SCHEMA = 1
# Staging directories are named ``.<name>.lfrefract-<8 random>.partial`` (earlier outputs moved
# aside: ``...old.partial``): the name is what marks them as this package's, so a stage starts empty
# (a render can be staged into a folder of another output's stage).
_STAGE_TAG = ".lfrefract-"
_STAGE_SUFFIX = ".partial"
_ASIDE_SUFFIX = ".old.partial"
_STAGE_NAME = re.compile(r"^\.(?P<name>.+)\.lfrefract-[a-z0-9_]{8}(?P<aside>\.old)?\.partial$")
_LOCK_ATTEMPTS = 8

# What this process is writing and has not finished: path -> is a directory (for terminate_cleanly).
_PENDING: dict[Path, bool] = {}
# Parents whose stale staging this process has removed (what is stale there now was left before it began).
_CLEANED_PARENTS: set[Path] = set()
_MAX_LISTED = 5  # paths named in a refusal; the rest are counted


# =============================================================================== files
def current_umask() -> int:
    """The process's file-mode creation mask, read without changing it (Linux), else by setting it back."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("Umask:"):
                return int(line.split()[1], 8)
    except OSError:
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _apply_umask(path: Path, *, directory: bool) -> None:
    """Give a file or directory made by mkstemp / mkdtemp (0600 / 0700) the mode that ``open`` or
    ``mkdir`` would have given it under the user's umask (0666 / 0777 less the mask)."""
    os.chmod(path, (0o777 if directory else 0o666) & ~current_umask())


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[Path]:
    """Write one file atomically: the project's single writer of files.

    Yields a temporary path beside ``path`` with a unique name (``.<name>.<random>.tmp``, so
    writers running at once never share one). When the block ends without an exception the file
    gets the mode the user's umask gives new files and is renamed over ``path``; on any exception
    (KeyboardInterrupt too) it is removed and ``path`` is left as it was.

    Parameters
    ----------
    path : path-like
        Destination file; its directory is created if needed.

    Raises
    ------
    IsADirectoryError
        If ``path`` is an existing directory (before anything is written).
    """
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(f"output file {str(path)!r} is an existing directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    _PENDING[tmp] = False
    try:
        yield tmp
        _apply_umask(tmp, directory=False)
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        named = _naming(exc, tmp, path)
        if named is exc:
            raise
        raise named from exc
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        _PENDING.pop(tmp, None)


def _naming(exc: OSError, written: Path, shown: str | os.PathLike) -> OSError:
    """``exc`` naming ``shown`` where it names no file or only ``written`` (a temporary name) or a path inside it.

    Python's low-level writes (``write``, ``flush``, ``close``) raise with ``filename`` unset, so a full
    disk said ``[Errno 28] No space left on device`` and no more; the user needs to know which output failed.
    Returns ``exc`` itself when it already names another path, or has no errno (its message says all).
    """
    if exc.errno is None:
        return exc
    name = exc.filename
    if name is None or name == str(written):
        name = str(shown)
    elif isinstance(name, str) and name.startswith(str(written) + os.sep):
        name = str(shown) + name[len(str(written)) :]
    else:
        return exc
    return OSError(exc.errno, exc.strerror, name, None, exc.filename2)


@contextlib.contextmanager
def scratch_directory(*, prefix: str) -> Iterator[Path]:
    """A temporary working folder that SIGTERM removes too (unlike ``tempfile.TemporaryDirectory``).

    Makes a fresh folder ``<prefix><random>`` in the system's temporary directory (``TMPDIR``
    honoured) and yields it; when the block ends, normally or by any exception, it is removed with
    everything in it. While the block runs it is registered as unfinished, so
    :func:`terminate_cleanly` removes it if the process is sent SIGTERM.

    Parameters
    ----------
    prefix : str
        Start of the folder's name (``"lfsim-planes-"``, say).

    Yields
    ------
    Path
        The new, empty folder.
    """
    path = Path(tempfile.mkdtemp(prefix=prefix))
    _PENDING[path] = True
    try:
        yield path
    finally:
        try:
            with contextlib.suppress(FileNotFoundError):
                shutil.rmtree(path)
        finally:
            _PENDING.pop(path, None)


# =============================================================================== inputs
def _resolved(path: str | os.PathLike) -> Path:
    """``path`` absolute with its links followed; a symbolic link loop is an :class:`OSError` naming
    it (``Path.resolve`` raises RuntimeError there, which would escape the commands as a traceback)."""
    try:
        return Path(os.path.abspath(Path(path).expanduser())).resolve()
    except RuntimeError:
        raise OSError(errno.ELOOP, "a symbolic link loop (the link points back to itself)", str(path)) from None


def refuse_own_inputs(outputs: Iterable[str | os.PathLike], inputs: Iterable[str | os.PathLike]) -> None:
    """Refuse outputs that are one of the inputs, or directories that hold one.

    Parameters
    ----------
    outputs : iterable of path-like
        Files or directories about to be written (or replaced).
    inputs : iterable of path-like
        Files the command reads (paths that do not exist are ignored).

    Raises
    ------
    FileExistsError
        Naming the output and the input it would destroy.
    """
    sources = [(str(p), _resolved(p)) for p in inputs if Path(p).exists()]
    for out in outputs:
        target = _resolved(out)
        for given, source in sources:
            if source == target or target in source.parents:
                what = "is" if source == target else "holds"
                raise FileExistsError(
                    f"output {str(out)!r} {what} the command's own input {given!r}: refusing to write over it"
                )


def _refuse_working_directory(out: Path, given: str | os.PathLike) -> None:
    cwd = Path.cwd().resolve()
    if out == cwd or out in cwd.parents:
        raise FileExistsError(
            f"output directory {str(given)!r} is the current directory or one of its parents: name a folder "
            "inside it (an output directory is replaced as a whole)"
        )
    if not out.name:
        raise FileExistsError(f"output directory {str(given)!r} is a filesystem root")


# =============================================================================== single files
@dataclass(frozen=True)
class ExpectedKind:
    """What an existing file must be for ``overwrite`` to replace it.

    Exactly one of the fields is set: ``exr_role`` (an EXR whose header role is this),
    ``json_kind`` (a JSON sidecar whose ``kind`` is this), or ``listed_in`` (a companion named in
    the ``files`` of the JSON sidecar at that path, itself of kind ``listed_kind``).
    """

    exr_role: str | None = None
    json_kind: str | None = None
    listed_in: Path | None = None
    listed_kind: str | None = None

    def __post_init__(self) -> None:
        given = [x is not None for x in (self.exr_role, self.json_kind, self.listed_in)]
        if sum(given) != 1 or (self.listed_in is not None) != (self.listed_kind is not None):
            raise ValueError(f"ExpectedKind needs exactly one of exr_role, json_kind, listed_in(+kind): {self!r}")

    def describe(self) -> str:
        if self.exr_role is not None:
            return f"an EXR image of role {self.exr_role!r}"
        if self.json_kind is not None:
            return f"a JSON sidecar of kind {self.json_kind!r}"
        return f"a file listed in the {self.listed_kind!r} sidecar {str(self.listed_in)!r}"


def _json_object(path: Path) -> dict | None:
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    return data if isinstance(data, dict) else None


def _exr_role(path: Path) -> str | None:
    import OpenEXR

    try:
        with path.open("rb") as fh:
            if fh.read(4) != b"\x76\x2f\x31\x01":
                return None
        with OpenEXR.File(str(path), header_only=True) as exr:
            role = exr.header().get("lfrefract_role")
    except (OSError, RuntimeError, ValueError, TypeError):
        return None
    return role if isinstance(role, str) else None


def _is_kind(path: Path, expected: ExpectedKind) -> bool:
    if expected.exr_role is not None:
        return _exr_role(path) == expected.exr_role
    if expected.json_kind is not None:
        data = _json_object(path)
        return data is not None and data.get("kind") == expected.json_kind
    listed_in = expected.listed_in
    assert listed_in is not None  # ExpectedKind holds exactly one of the three
    sidecar = _json_object(Path(listed_in))
    if sidecar is None or sidecar.get("kind") != expected.listed_kind:
        return False
    files = sidecar.get("files")
    return isinstance(files, dict) and path.name in [v for v in files.values() if isinstance(v, str)]


def prepare_output_files(
    outputs: Mapping[Path, ExpectedKind] | Mapping[str, ExpectedKind],
    *,
    inputs: Iterable[str | os.PathLike] = (),
    overwrite: bool = False,
) -> None:
    """Check, before anything is written, that a command may write these files.

    Parameters
    ----------
    outputs : mapping of path-like to ExpectedKind
        Every file the command will write, with what an existing one must be to be replaced.
    inputs : iterable of path-like
        Every file the command reads: none may be an output.
    overwrite : bool
        Replace existing outputs of the expected kinds (without it, any existing output is refused).

    Raises
    ------
    FileExistsError
        If an output is an input, is a directory, or exists and may not be replaced; the message
        names the path and what is in the way.
    """
    paths = {Path(p): kind for p, kind in outputs.items()}
    resolved = [_resolved(p) for p in paths]
    if len(set(resolved)) != len(resolved):
        raise FileExistsError(f"two outputs are the same file: {sorted(str(p) for p in paths)}")
    refuse_own_inputs(paths, inputs)
    for path, expected in paths.items():
        if path.is_dir():
            raise FileExistsError(f"output file {str(path)!r} is an existing directory")
        if not (path.exists() or path.is_symlink()):
            continue
        if not overwrite:
            raise FileExistsError(f"output {str(path)!r} exists (pass --overwrite to replace an earlier output)")
        if path.is_symlink() or not path.is_file():
            raise FileExistsError(f"output {str(path)!r} is not a regular file: refusing to replace it")
        if not _is_kind(path, expected):
            raise FileExistsError(
                f"output {str(path)!r} exists and is not {expected.describe()}: refusing to replace it"
            )


# =============================================================================== directories
def output_manifest(directory: str | os.PathLike) -> dict | None:
    """The manifest of an output directory written by :func:`staged_directory`, or None.

    Returns
    -------
    dict or None
        ``{"kind": str, "files": {relative POSIX path: bytes}, "directories": [relative path]}``,
        or None if the directory holds no readable manifest.
    """
    data = _json_object(Path(directory) / MANIFEST_NAME)
    if data is None or data.get("schema_version") != _MANIFEST_SCHEMA:
        return None
    kind, files, dirs = data.get("kind"), data.get("files"), data.get("directories")
    if not (isinstance(kind, str) and isinstance(files, dict) and isinstance(dirs, list)):
        return None
    if not all(isinstance(k, str) and isinstance(v, int) for k, v in files.items()):
        return None
    return {"kind": kind, "files": files, "directories": [d for d in dirs if isinstance(d, str)]}


def _walk(directory: Path) -> tuple[dict[str, os.stat_result], list[str]]:
    """Every non-directory entry (relative POSIX path -> lstat) and every folder under ``directory``."""
    entries, folders = {}, []
    for root, dirnames, filenames in os.walk(directory):
        base = Path(root)
        for name in dirnames:
            full = base / name
            rel = full.relative_to(directory).as_posix()
            if full.is_symlink():  # os.walk does not descend into it; it is an entry, not a folder
                entries[rel] = full.lstat()
            else:
                folders.append(rel)
        for name in filenames:
            full = base / name
            entries[full.relative_to(directory).as_posix()] = full.lstat()
    return entries, sorted(folders)


def _write_manifest(stage: Path, kind: str) -> None:
    entries, folders = _walk(stage)
    entries.pop(MANIFEST_NAME, None)
    manifest = {
        "schema_version": _MANIFEST_SCHEMA,
        "kind": kind,
        "note": "the files of this lfrefract output: --overwrite replaces it only while it holds just these",
        "files": {rel: st.st_size for rel, st in sorted(entries.items())},
        "directories": folders,
    }
    with atomic_file(stage / MANIFEST_NAME) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")


def _refuse_replacing(out: Path, kind: str) -> None:
    """Raise unless ``out`` is an output of ``kind`` holding only the files its manifest lists."""
    manifest = output_manifest(out)
    if manifest is None:
        raise FileExistsError(
            f"output directory {str(out)!r} is not empty and is not an lfrefract output (no readable {MANIFEST_NAME}): "
            "refusing to replace it"
        )
    if manifest["kind"] != kind:
        raise FileExistsError(
            f"output directory {str(out)!r} holds an output of kind {manifest['kind']!r}, not {kind!r}: "
            "refusing to replace it"
        )
    entries, folders = _walk(out)
    listed, listed_dirs = manifest["files"], set(manifest["directories"])
    problems = [f"{rel!r} (a folder it did not make)" for rel in folders if rel not in listed_dirs]
    for rel, st in sorted(entries.items()):
        if rel == MANIFEST_NAME:
            continue
        if rel not in listed:
            problems.append(f"{rel!r} (not written by it)")
        elif not stat.S_ISREG(st.st_mode):
            problems.append(f"{rel!r} (no longer a regular file)")
        elif st.st_size != listed[rel]:
            problems.append(f"{rel!r} (changed: {st.st_size} bytes, written as {listed[rel]})")
    if problems:
        shown = ", ".join(problems[:_MAX_LISTED])
        more = f" and {len(problems) - _MAX_LISTED} more" if len(problems) > _MAX_LISTED else ""
        raise FileExistsError(
            f"output directory {str(out)!r} is an earlier {kind} output but holds what it did not write: "
            f"{shown}{more}; refusing to replace it"
        )


def _try_lock(path: Path) -> int | None:
    """An open descriptor of ``path`` holding an exclusive flock, or None if another process holds one."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        return None
    return fd


def remove_stale_staging(parent: str | os.PathLike) -> list[Path]:
    """Remove what killed writers left in ``parent``; put back earlier outputs they had moved aside.

    A staging directory (``.<name>.lfrefract-<random>.partial``) that no live process holds
    locked is deleted. An earlier output moved aside for replacement
    (``.<name>.lfrefract-<random>.old.partial``, holding its manifest) is renamed back to
    ``<name>`` if nothing has taken that name, else deleted (the new output is in place); an empty
    one is deleted. Nothing else is touched.

    Returns
    -------
    list of Path
        What was removed or put back.
    """
    parent = Path(parent)
    done: list[Path] = []
    try:
        names = sorted(p.name for p in parent.iterdir())
    except OSError:
        return done
    for match in filter(None, map(_STAGE_NAME.match, names)):
        path = parent / match.string
        if path.is_symlink() or not path.is_dir():
            continue
        fd = _try_lock(path)
        if fd is None:
            continue  # a live writer holds it
        try:
            if match["aside"]:
                original = parent / match["name"]
                if output_manifest(path) is not None and not (original.exists() or original.is_symlink()):
                    os.replace(path, original)
                elif output_manifest(path) is not None or not any(path.iterdir()):
                    shutil.rmtree(path)
                else:
                    continue
            else:
                shutil.rmtree(path)
            done.append(path)
        except OSError:
            pass  # left for a later run; never fatal to this one
        finally:
            os.close(fd)
    return done


def _locked_directory(parent: Path, name: str, suffix: str) -> tuple[Path, int]:
    """A new empty directory ``.<name>.lfrefract-<random><suffix>`` in ``parent``, locked.

    Another writer's :func:`remove_stale_staging` may take a directory in the instant between its
    creation and its lock; then another name is tried.
    """
    for _ in range(_LOCK_ATTEMPTS):
        path = Path(tempfile.mkdtemp(prefix=f".{name}{_STAGE_TAG}", suffix=suffix, dir=parent))
        fd = _try_lock(path)
        if fd is not None and path.is_dir():
            return path, fd
        if fd is not None:
            os.close(fd)
        with contextlib.suppress(OSError):
            path.rmdir()
    raise OSError(f"could not create a locked staging directory in {str(parent)!r}")


@contextlib.contextmanager
def staged_directory(
    out_dir: str | os.PathLike,
    *,
    kind: str,
    overwrite: bool = False,
    inputs: Iterable[str | os.PathLike] = (),
) -> Iterator[Path]:
    """Assemble an output directory atomically, and replace only what may be replaced.

    Yields a fresh staging directory beside ``out_dir`` (held under an flock while the block
    runs). When the block finishes without an exception, the manifest (``MANIFEST_NAME``: the
    kind, every file with its size, every folder) is written into it and it takes the place of
    ``out_dir``; on any exception it is deleted and ``out_dir`` is left as it was. An earlier
    output being replaced is first renamed aside and deleted only after the new one is in place.
    Stale staging directories of killed writers in the same parent are removed first, once per
    parent and process (:func:`remove_stale_staging`). Directories get the mode the user's umask gives.

    Parameters
    ----------
    out_dir : path-like
        The directory to create or replace (resolved first: ``.`` or a parent of the current
        directory is refused).
    kind : str
        What the output is (``"lfsim.render"``, ``"lfrefract.view_stack"``, ...).
    overwrite : bool
        Replace an earlier output of the same ``kind`` that holds only the files its manifest lists.
    inputs : iterable of path-like
        Files the command reads: ``out_dir`` may not be one of them nor hold one.

    Raises
    ------
    FileExistsError
        If ``out_dir`` is a file, the current directory, holds an input, or is not empty and may
        not be replaced (the message names the path and what is in the way).
    """
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"kind must be a non-empty string, got {kind!r}")
    out = _resolved(out_dir)
    _refuse_working_directory(out, out_dir)
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"output {str(out_dir)!r} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not overwrite:
            raise FileExistsError(
                f"output directory {str(out_dir)!r} is not empty (pass --overwrite to replace an earlier {kind} output)"
            )
        refuse_own_inputs([out], inputs)
        _refuse_replacing(out, kind)
    out.parent.mkdir(parents=True, exist_ok=True)
    parent = out.parent.resolve()
    if parent not in _CLEANED_PARENTS:  # once per parent and process: a dataset stages 10^5 samples in one folder
        remove_stale_staging(parent)
        _CLEANED_PARENTS.add(parent)
    stage, lock = _locked_directory(out.parent, out.name, _STAGE_SUFFIX)
    _PENDING[stage] = True
    try:
        yield stage
        _write_manifest(stage, kind)
        _apply_umask(stage, directory=True)
        _commit(stage, out)
    except OSError as exc:
        shutil.rmtree(stage, ignore_errors=True)
        named = _naming(exc, stage, out_dir)
        if named is exc:
            raise
        raise named from exc
    except BaseException:
        shutil.rmtree(stage, ignore_errors=True)
        raise
    finally:
        _PENDING.pop(stage, None)
        os.close(lock)


def _commit(stage: Path, out: Path) -> None:
    """Put the content of ``stage`` in the place of ``out``.

    ``out`` absent: ``stage`` is renamed to it. ``out`` an empty directory (one the user made, or
    the stage of an enclosing output): the entries move into it, the manifest last, so the folder
    itself (and a lock or a shell's working directory on it) stays. ``out`` an earlier output: it
    is moved aside and deleted only after the new one is in place (at no moment is neither on
    disk; a failed rename puts it back).
    """
    if not out.exists():
        os.replace(stage, out)
        return
    if not any(out.iterdir()):
        names = sorted((p.name for p in stage.iterdir()), key=lambda n: n == MANIFEST_NAME)
        for name in names:
            os.replace(stage / name, out / name)
        stage.rmdir()
        return
    aside, aside_lock = _locked_directory(out.parent, out.name, _ASIDE_SUFFIX)
    try:
        os.replace(out, aside)
        try:
            os.replace(stage, out)
        except BaseException:
            os.replace(aside, out)
            raise
        shutil.rmtree(aside, ignore_errors=True)
    finally:
        os.close(aside_lock)


@contextlib.contextmanager
def terminate_cleanly(prog: str, *, resumable: bool = False) -> Iterator[None]:
    """Make SIGTERM and SIGINT (Ctrl-C) remove this process's unfinished outputs before it ends.

    Python's default for SIGTERM ends the process with no cleanup, leaving staging directories and
    temporary files; its default for SIGINT raises KeyboardInterrupt wherever the main thread is, which
    can be inside native code or a module's import (Dr.Jit, OpenEXR) and then ends in a traceback of
    unrelated errors. So the handler runs the callbacks registered with :func:`on_termination` (the
    newest first: a dataset run stops its worker processes there), deletes what
    :func:`staged_directory`, :func:`atomic_file` and :func:`scratch_directory` have not finished, says
    so in one line on standard error and ends the process at once: exit status 143 for SIGTERM, 130 for
    SIGINT. An earlier output caught between the two renames of a replacement is put back by the next
    run (:func:`remove_stale_staging`).

    Parameters
    ----------
    prog : str
        The command's name, which starts the line.
    resumable : bool
        The command resumes where it stopped when run again (the line says so).

    Only the main thread can install signal handlers; elsewhere the block runs unchanged. The
    previous handlers are restored afterwards.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def _terminate(signum, frame):
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # a second Ctrl-C does not cut the cleanup short
        for callback in _ON_TERMINATION[::-1]:
            with contextlib.suppress(Exception):
                callback()
        for path, directory in list(_PENDING.items())[::-1]:
            with contextlib.suppress(OSError):
                shutil.rmtree(path) if directory else path.unlink()
        if signum == signal.SIGINT:
            line = f"{prog}: interrupted; unfinished outputs removed" + ("; run again to resume" if resumable else "")
        else:
            line = f"{prog}: terminated (signal {signum}); unfinished outputs removed"
        with contextlib.suppress(OSError):
            os.write(2, f"{line}\n".encode())
        os._exit(128 + signum)

    previous = {signum: signal.signal(signum, _terminate) for signum in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


# Callbacks terminate_cleanly runs before it removes the unfinished outputs (see on_termination).
_ON_TERMINATION: list = []


@contextlib.contextmanager
def on_termination(callback) -> Iterator[None]:
    """While the block runs, :func:`terminate_cleanly`'s handler calls ``callback()`` before it removes
    the unfinished outputs (a dataset run stops its worker processes there, so none writes on).

    Parameters
    ----------
    callback : callable
        Takes no arguments; its exceptions are ignored (the process is ending).
    """
    _ON_TERMINATION.append(callback)
    try:
        yield
    finally:
        _ON_TERMINATION.remove(callback)
