"""Where results come from, and writing files whole: the code version (package version, git
commit, dirty flag) that the run store records, the code and runtime record (`code_record`)
that the studies' sidecars and `SimulationResult`'s files share, and `write_atomic`, which every
writer of results uses."""

from __future__ import annotations

import datetime
import errno
import hashlib
import os
import platform
import subprocess
import threading
from pathlib import Path
from typing import Callable, Dict, Optional, Tuple

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["code_record", "code_version", "table_stamp", "write_atomic"]


def code_version() -> Dict[str, object]:
    """{"version": the package version, "commit": git HEAD of the source checkout or None,
    "dirty": whether tracked files differ from it (None outside git)}, and where they do,
    "changes_sha256": the SHA-256 of those differences (`git diff HEAD`), so that two edits of
    one commit are two versions (a run resumed after another edit of a dirty checkout mixed
    the two codes' chunks without the warning a version change gives; an audit)."""
    from . import __version__
    root = Path(__file__).resolve().parents[1]
    commit = dirty = changes = None
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True,
                              text=True, timeout=10)
        if head.returncode == 0 and head.stdout.strip():
            commit = head.stdout.strip()
            status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"],
                                    cwd=root, capture_output=True, text=True, timeout=10)
            dirty = bool(status.stdout.strip()) if status.returncode == 0 else None
            if dirty:
                diff = subprocess.run(["git", "diff", "HEAD", "--no-color", "--no-ext-diff"],
                                      cwd=root, capture_output=True, timeout=60)
                if diff.returncode == 0:
                    changes = hashlib.sha256(diff.stdout).hexdigest()
    except (OSError, subprocess.SubprocessError):
        pass
    version = {"version": __version__, "commit": commit, "dirty": dirty}
    return version if changes is None else {**version, "changes_sha256": changes}


def taichi_version() -> str:
    """The installed Taichi's version, "1.7.3" (Taichi gives it as a tuple or a string)."""
    import taichi

    version = taichi.__version__
    return ".".join(map(str, version)) if isinstance(version, (tuple, list)) else str(version)


def code_record() -> Dict[str, object]:
    """What made a result, as every sidecar records it (`output.provenance`, the studies'
    `record`): taichi_star_version, git_commit, git_dirty (`code_version`), and for a dirty
    checkout git_changes_sha256 (which edits of the commit, so that two are told apart);
    taichi_version, python_version, and the date (ISO 8601, local time, to the second)."""
    code = code_version()
    return {"taichi_star_version": code["version"], "git_commit": code["commit"],
            "git_dirty": code["dirty"],
            **({"git_changes_sha256": code["changes_sha256"]} if "changes_sha256" in code
               else {}),
            "taichi_version": taichi_version(), "python_version": platform.python_version(),
            "date": datetime.datetime.now().astimezone().isoformat(timespec="seconds")}


def file_path(path, what: str) -> Path:
    """`path` as a Path; ValueError naming `what` (e.g. "path of the CSV file") unless it is
    a str or an os.PathLike, before anything is computed or written."""
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path must be the {what}, got {type(path).__name__}")
    return Path(path)


TEMPORARY_MARK = ".tmp-"
"""`write_atomic` writes NAME first as ".NAME.tmp-PID-THREAD" (`is_temporary`)."""
_WRITE_LOCKS: Dict[str, threading.Lock] = {}
"""One lock per file `write_atomic` writes in this process (`_write_lock`)."""
_WRITE_LOCKS_GUARD = threading.Lock()


def _fresh_write_locks_in_child():
    """A forked child's own write locks (the parent's threads holding them are not in it)."""
    global _WRITE_LOCKS, _WRITE_LOCKS_GUARD
    _WRITE_LOCKS, _WRITE_LOCKS_GUARD = {}, threading.Lock()


os.register_at_fork(after_in_child=_fresh_write_locks_in_child)


def _write_lock(path: Path) -> threading.Lock:
    """The lock of writes to `path` in this process: two threads writing one file (a table and
    its sidecar) take turns. Without it, each deleted the other's temporaries and 158 of 800
    writes failed, and 6 of 40 rounds left a table without its sidecar (an audit, 2026-12)."""
    with _WRITE_LOCKS_GUARD:
        return _WRITE_LOCKS.setdefault(os.path.abspath(path), threading.Lock())


def is_temporary(path: Path) -> bool:
    """Whether `path` names a temporary file of `write_atomic`, left whole or not by a killed
    writer: never a result."""
    return path.name.startswith(".") and TEMPORARY_MARK in path.name


TABLE_SHA256 = "table_sha256"
"""The key of a CSV sidecar's stamp of its table (`table_stamp`)."""


def table_stamp(rows: int, data: bytes) -> Dict[str, object]:
    """What a CSV's sidecar records of the table it describes: its rows and the SHA-256 of its
    bytes (`output.read_provenance` refuses a table that is no longer that one)."""
    return {"table_rows": rows, TABLE_SHA256: hashlib.sha256(data).hexdigest()}


def require_folder(path: Path, failure: Callable[[str], Exception] = OSError):
    """Raise `failure(reason)` unless the folder `path` goes into is one ("cannot write x.csv:
    its folder /data/run does not exist"): the writers create no folders, and a message naming
    only the file does not say which folder is missing. Call it before computing what to
    write."""
    folder = path.parent
    if not folder.is_dir():
        reason = "is not a folder" if folder.exists() else "does not exist"
        raise failure(f"cannot write {path.name}: its folder {folder} {reason}")


def write_atomic(path, data: bytes, failure: Optional[Callable[[str], Exception]] = None,
                 sidecar: Optional[Tuple[Path, bytes]] = None):
    """Write `data` to `path` whole or not at all: into a temporary file beside it, flushed to
    disk, then renamed over it; a kill or a full disk leaves any previous file untouched. With
    `failure`, an OSError (a full disk) is raised as `failure(reason)` instead, the reason one
    line naming the file and the error ("cannot write x.csv (No space left on device)"), or
    its folder where that is missing (`require_folder`).

    `sidecar` (its path and data: the file's description) is written with it: both go to
    temporary files first, then the previous sidecar is moved aside, the file renamed into
    place (the previous sidecar put back if that fails) and the sidecar after it. A full disk
    then leaves both previous files as they were, and a kill at worst the new file without a
    sidecar, never beside the previous one's (which describes another result)."""
    with _write_lock(Path(path)):
        _write_atomic(path, data, failure, sidecar)


def _write_atomic(path, data: bytes, failure: Optional[Callable[[str], Exception]],
                  sidecar: Optional[Tuple[Path, bytes]]):
    """`write_atomic`, its file's lock held."""
    targets = [(Path(path), data)] + ([(Path(sidecar[0]), sidecar[1])] if sidecar else [])
    writer = f"{os.getpid()}-{threading.get_ident()}"
    temporaries = [target.with_name(f".{target.name}{TEMPORARY_MARK}{writer}")
                   for target, _ in targets]
    previous = temporaries[-1].with_name(f"{temporaries[-1].name}.previous")
    if failure is not None:
        for target, _ in targets:
            require_folder(target, failure)
    current = targets[0][0]
    try:
        for current, _ in targets:
            if current.is_dir():  # before anything moves (a folder would be moved aside)
                raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR))
        for (current, content), temporary in zip(targets, temporaries):
            with open(temporary, "wb") as handle:
                handle.write(content)
                handle.flush()
                os.fsync(handle.fileno())
        current = targets[0][0]  # moving the previous sidecar aside is part of the table's write
        try:
            if sidecar and os.path.lexists(targets[1][0]):
                os.replace(targets[1][0], previous)
            os.replace(temporaries[0], current)
        except BaseException:
            # Ctrl-C too, which Python raises after the system call in progress: the table's
            # temporary still there says its rename did not happen, and the previous table
            # keeps its sidecar; renamed, the new table stands without one
            if os.path.lexists(temporaries[0]) and os.path.lexists(previous):
                os.replace(previous, targets[1][0])
            raise
        if sidecar:
            current = targets[1][0]
            os.replace(temporaries[1], current)
    except OSError as error:
        if failure is None:
            raise
        raise failure(f"cannot write {current.name} ({error.strerror or error})") from None
    finally:
        # what is left is never a result: the new data unrenamed, or a sidecar moved aside
        # whose table has been replaced (a kill between the move and the table's rename
        # leaves it as `.NAME.tmp-PID-THREAD.previous`, the table's temporary beside it: then
        # it is the sidecar of the table still there)
        for temporary in (*temporaries, previous):
            try:
                if os.path.lexists(temporary):
                    os.unlink(temporary)
            except OSError:  # best effort: the write itself is done or has failed already
                pass
    _sync_folder(targets[0][0].parent)


def _sync_folder(folder: Path):
    """Flush a folder's entries to disk, so that a rename into it outlives a power cut (until
    then the folder may still name the previous file after a restart). Best effort: a system
    that cannot open a folder for it (Windows) or does not sync folders leaves the rename to
    its own schedule, the file's data already on disk either way."""
    try:
        descriptor = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(descriptor)
    except OSError:
        pass
    finally:
        os.close(descriptor)
