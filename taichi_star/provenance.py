"""Where results come from, and writing files whole: the code version (package version, git
commit, dirty flag) that the run store records, the code and runtime record (`code_record`)
that the studies' sidecars and `SimulationResult`'s files share, and `write_atomic`, which every
writer of results uses."""

from __future__ import annotations

import datetime
import errno
import hashlib
import importlib.metadata
import json
import math
import os
import platform
import re
import subprocess
import threading
from pathlib import Path
from typing import Callable, Dict, List, Mapping, Optional, Tuple

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["code_record", "code_version", "library_versions", "local_time", "machine",
           "cpu_model", "vector_extensions", "cache_sizes", "nvidia_smi", "table_stamp",
           "write_atomic", "finite_json", "provenance_json"]


def _git(root: Path, *arguments: str, timeout: float = 10) -> Optional[bytes]:
    """The output of `git ARGUMENTS` run in `root`, None where git fails or is missing."""
    try:
        done = subprocess.run(["git", *arguments], cwd=root, capture_output=True, timeout=timeout)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout if done.returncode == 0 else None


PACKAGE_FOLDERS = ("taichi_star", "studies")
"""The folders of a checkout whose untracked files are code (`code_version`): a new module
changes what runs; an untracked file elsewhere (notes, a scratch table) does not."""


def _source_checkout(root: Path) -> bool:
    """Whether `root` (the folder above the package) is the top of a git checkout whose HEAD
    holds this module: a taichi_star installed into someone else's repository (its .venv/
    inside that repository) recorded that repository's commit and dirty flag (an audit). HEAD's
    tree, not the index, so that a damaged index still names the commit."""
    top = _git(root, "rev-parse", "--show-toplevel")
    if top is None or Path(os.fsdecode(top.strip())).resolve() != root:
        return False
    module = Path(__file__).resolve().relative_to(root).as_posix()
    return bool(_git(root, "ls-tree", "--name-only", "HEAD", "--", module))


def _untracked_package_files(root: Path) -> Optional[List[str]]:
    """The untracked (not ignored) files under `PACKAGE_FOLDERS`, paths relative to `root`
    in git's order; None where git cannot list them."""
    listed = _git(root, "ls-files", "-z", "--others", "--exclude-standard", "--",
                  *PACKAGE_FOLDERS)
    return None if listed is None else [os.fsdecode(name) for name in listed.split(b"\0")
                                        if name]


def _source_files(root: Path) -> List[Tuple[str, Path]]:
    """The package's files under `root` (the folder above it) as (path relative to `root`,
    file), sorted by path: taichi_star/ (an installed package holds its studies there), and
    for a folder's editable install the studies/ beside it; byte code left out (Python writes
    it as it imports)."""
    folders = [root / "taichi_star"]
    if not (root / "taichi_star" / "studies").is_dir():
        folders.append(root / "studies")
    found = []
    for folder in folders:
        for where, subfolders, names in os.walk(folder):
            subfolders[:] = [name for name in subfolders if name != "__pycache__"]
            found += [(Path(where, name).relative_to(root).as_posix(), Path(where, name))
                      for name in names if not name.endswith((".pyc", ".pyo"))]
    return sorted(found)


def _source_sha256(root: Path) -> Optional[str]:
    """The SHA-256 of the package's files (`_source_files`: each file's path, its length and
    its content, in order of path): what names the code where no commit does (a wheel, a
    folder's install; two builds of one version were one version, and a run store resumed
    with the other mixed their chunks unwarned: an audit). None where a file cannot be read."""
    digest = hashlib.sha256()
    try:
        for name, path in _source_files(root):
            content = path.read_bytes()
            digest.update(f"{name}\0{len(content)}\0".encode() + content)
    except OSError:
        return None
    return digest.hexdigest()


COMMIT_ID = re.compile(r"[0-9a-f]{40}|[0-9a-f]{64}")
"""A git object name: SHA-1 (40 hex digits) or SHA-256 (64)."""


def _installed_commit(root: Path, version: str) -> Optional[str]:
    """The git commit pip recorded for the distribution of this package at `version` installed
    beside it in `root` (its dist-info's direct_url.json, PEP 610: `vcs_info.commit_id` of an
    install from a git URL, `pip install git+https://...@REF`), None where there is none (a
    wheel, a folder, a damaged record) or where it is not the one distribution of that name
    and version there. An upgrade by `pip install --target` leaves the older version's
    dist-info beside the new one, and the first listed was taken: the new code recorded as
    the old commit, clean (a review, 2026-12). That install is exactly the commit's tree, as
    far as pip knows."""
    ours = [distribution for distribution in importlib.metadata.distributions(path=[str(root)])
            if _name_and_version(distribution) == ("taichi_star", version)]
    if len(ours) != 1:
        return None
    try:
        record = json.loads(ours[0].read_text("direct_url.json") or "{}")
    except (OSError, ValueError):
        return None
    vcs = record.get("vcs_info") if isinstance(record, dict) else None
    if not isinstance(vcs, dict) or vcs.get("vcs") != "git":
        return None
    commit = vcs.get("commit_id")
    return commit if isinstance(commit, str) and COMMIT_ID.fullmatch(commit) else None


def _name_and_version(distribution) -> Tuple[str, Optional[str]]:
    """A distribution's name as PEP 503 compares names ("_" for the separators) and its
    version; ("", None) for a dist-info without metadata (one a failed uninstall left: newer
    Pythons and the importlib_metadata backport, whose finders the stdlib's discovery also
    asks, give none or raise MetadataNotFound, a FileNotFoundError, or KeyError for a missing
    field)."""
    try:
        metadata = distribution.metadata
        name, version = metadata.get("Name"), metadata.get("Version")
    except (AttributeError, KeyError, OSError, TypeError, ValueError):
        return "", None
    return re.sub(r"[-_.]+", "_", name or "").lower(), version


def code_version() -> Dict[str, object]:
    """{"version": the package version, "commit": git HEAD of the package's own checkout or
    None, "dirty": whether its tracked files differ from that commit or untracked files lie in
    taichi_star/ or studies/ (None outside git)}, and where it is dirty, "changes_sha256": the
    SHA-256 of those differences (`git diff HEAD`, then each untracked file's path and
    content), so that two edits of one commit are two versions (a run resumed after another
    edit of a dirty checkout mixed the two codes' chunks without the warning a version change
    gives; an audit). Outside its own checkout the commit is the one pip recorded where the
    package was installed from a git URL, and clean (`_installed_commit`); otherwise None: a
    package installed inside another repository records that repository's nothing. Where no
    commit names the code (a wheel, a folder's install, a checkout without commits),
    "source_sha256" does: the hash of the package's files (`_source_sha256`)."""
    from . import __version__
    root = Path(__file__).resolve().parents[1]
    commit = dirty = changes = None
    in_checkout = _source_checkout(root)
    head = _git(root, "rev-parse", "HEAD") if in_checkout else None
    if head and head.strip():
        commit = head.decode().strip()
        status = _git(root, "status", "--porcelain", "--untracked-files=no")
        untracked = _untracked_package_files(root)
        if status is not None and untracked is not None:
            dirty = bool(status.strip() or untracked)
        if dirty:
            diff = _git(root, "diff", "HEAD", "--no-color", "--no-ext-diff", timeout=60)
            if diff is not None:
                digest = hashlib.sha256(diff)
                for name in untracked:
                    try:
                        content = (root / name).read_bytes()
                    except OSError:  # removed since it was listed: counted as gone
                        content = b""
                    digest.update(b"\0untracked\0" + name.encode() + b"\0" + content)
                changes = digest.hexdigest()
    elif not in_checkout:
        commit = _installed_commit(root, __version__)
        dirty = False if commit else None
    version = {"version": __version__, "commit": commit, "dirty": dirty}
    if commit is None:
        version["source_sha256"] = _source_sha256(root)
    return version if changes is None else {**version, "changes_sha256": changes}


def taichi_version() -> str:
    """The installed Taichi's version, "1.7.3" (Taichi gives it as a tuple or a string)."""
    import taichi

    version = taichi.__version__
    return ".".join(map(str, version)) if isinstance(version, (tuple, list)) else str(version)


RECORDED_LIBRARIES = ("numpy", "scipy", "pandas", "cma", "SALib", "dask", "distributed",
                      "gymnasium", "stable-baselines3", "torch")
"""The distributions whose versions a result records (`library_versions`): a CMA-ES run's
samples are cma's for a given seed, L-BFGS-B's and least squares' steps scipy's, the Sobol
design SALib's, and every table's arithmetic NumPy's and pandas'; a new version of one can move
a result that the same commit and seed made before. The Dask cluster's (a timing of `scaling`
on it) and the environments' and their client's (`env_bench`'s steps through Gymnasium, a
policy trained by SB3 on torch) are recorded too (left out until an audit, 2026-12)."""


def library_versions(names=RECORDED_LIBRARIES) -> Dict[str, Optional[str]]:
    """The installed version of each distribution of `names` ({"numpy": "1.26.4", ...}), None
    for one not installed (a plain install has no cma or SALib)."""
    versions = {}
    for name in names:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def local_time() -> str:
    """Now, as the result files record a date: ISO 8601, local time with its offset, to the
    second."""
    return datetime.datetime.now().astimezone().isoformat(timespec="seconds")


def code_record() -> Dict[str, object]:
    """What made a result, as every sidecar records it (`output.provenance`, the studies'
    `record`): taichi_star_version, git_commit, git_dirty (`code_version`), and for a dirty
    checkout git_changes_sha256 (which edits of the commit, so that two are told apart), where
    no commit is known source_sha256 (the hash of the package's files); taichi_version,
    python_version, library_versions (`library_versions`), and the date (`local_time`)."""
    code = code_version()
    return {"taichi_star_version": code["version"], "git_commit": code["commit"],
            "git_dirty": code["dirty"],
            **({"git_changes_sha256": code["changes_sha256"]} if "changes_sha256" in code
               else {}),
            **({"source_sha256": code["source_sha256"]} if "source_sha256" in code else {}),
            "taichi_version": taichi_version(), "python_version": platform.python_version(),
            "library_versions": library_versions(), "date": local_time()}


def cpuinfo_text() -> str:
    """The text of /proc/cpuinfo ("" where there is none)."""
    try:
        return Path("/proc/cpuinfo").read_text()
    except OSError:
        return ""


def cpu_model(cpuinfo: Optional[str] = None) -> str:
    """The CPU model name from the text of /proc/cpuinfo (read when not given;
    platform.processor() where it names none)."""
    for line in (cpuinfo_text() if cpuinfo is None else cpuinfo).splitlines():
        if line.lower().startswith("model name"):
            return line.split(":", 1)[1].strip()
    return platform.processor() or platform.machine() or "unknown"


VECTOR_EXTENSIONS = ("sse2", "avx", "fma", "avx2", "avx512f", "asimd", "sve")
"""The CPU's vector instruction sets a sidecar names, from /proc/cpuinfo's flags (x86) or
features (Arm), each family from the narrowest to the widest, so that the last one a CPU has
is its widest: which lanes LLVM can use for a kernel, why one machine's figures differ from
another's."""


def vector_extensions(cpuinfo: str) -> list:
    """The VECTOR_EXTENSIONS among the first processor's flags (or features) in the text of
    /proc/cpuinfo, in VECTOR_EXTENSIONS's order."""
    for line in cpuinfo.splitlines():
        name, _, value = line.partition(":")
        if name.strip().lower() in ("flags", "features"):
            flags = set(value.split())
            return [extension for extension in VECTOR_EXTENSIONS if extension in flags]
    return []


def cache_sizes(cache_folder: Path) -> Dict[str, str]:
    """{"L1d", "L1i", "L2", "L3": size as the kernel writes it, "48K"} of the caches in a
    /sys/devices/system/cpu/cpuN/cache folder (empty where there is none): with the cores, what
    decides whether a batch's matrices stay in cache."""
    sizes = {}
    for index in sorted(cache_folder.glob("index*")):
        try:
            level = (index / "level").read_text().strip()
            kind = (index / "type").read_text().strip()
            size = (index / "size").read_text().strip()
        except OSError:
            continue
        suffix = {"Data": "d", "Instruction": "i"}.get(kind, "")
        sizes[f"L{level}{suffix}"] = size
    return sizes


def nvidia_smi(query: str) -> list:
    """One line per NVIDIA GPU of `nvidia-smi --query-gpu=query` (empty without nvidia-smi)."""
    try:
        output = subprocess.run(["nvidia-smi", f"--query-gpu={query}", "--format=csv,noheader"],
                                capture_output=True, text=True, timeout=30, check=True).stdout
    except (OSError, subprocess.SubprocessError):
        return []
    return [line.strip() for line in output.splitlines() if line.strip()]


def gpu_names() -> list:
    """The names of the NVIDIA GPUs nvidia-smi lists (empty without nvidia-smi)."""
    return nvidia_smi("name")


def machine() -> Dict[str, object]:
    """cpu_model, cores, vector_extensions, caches (`cache_sizes`), gpus, platform of this
    machine."""
    cpuinfo = cpuinfo_text()
    return {"cpu_model": cpu_model(cpuinfo), "cores": os.cpu_count(),
            "vector_extensions": vector_extensions(cpuinfo),
            "caches": cache_sizes(Path("/sys/devices/system/cpu/cpu0/cache")),
            "gpus": gpu_names(), "platform": platform.platform()}


def finite_json(value):
    """`value` (mappings, lists and tuples of numbers and text) with every non-finite float
    (NaN, ±inf) as None, for JSON: Python's json writes NaN, which is not JSON (a run of no
    measurable time made `"robot_steps_per_s": NaN`, and JSON readers refused the sidecar: an
    audit)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {key: finite_json(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [finite_json(item) for item in value]
    return value


def provenance_json(facts: Mapping, indent: Optional[int] = None,
                    default: Callable[[object], str] = str) -> str:
    """`facts` as strict JSON text: non-finite numbers as null (`finite_json`), anything JSON
    has no type for as `default(value)` (its text), and a ValueError rather than a NaN should
    one be left."""
    return json.dumps(finite_json(facts), indent=indent, default=default, allow_nan=False)


def file_path(path, what: str) -> Path:
    """`path` as a Path; ValueError naming `what` (e.g. "path of the CSV file") unless it is
    a str or an os.PathLike naming a file ("", ".", "/" name none), before anything is
    computed or written."""
    if not isinstance(path, (str, os.PathLike)):
        raise ValueError(f"path must be the {what}, got {type(path).__name__}")
    if Path(path).name == "":  # "" is Path("."): pathlib's error named no argument
        raise ValueError(f"path must be the {what}, got {os.fspath(path)!r}, which names no "
                         f"file")
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
                 sidecar: Optional[Tuple[Path, Optional[bytes]]] = None):
    """Write `data` to `path` whole or not at all: into a temporary file beside it, flushed to
    disk, then renamed over it; a kill or a full disk leaves any previous file untouched. With
    `failure`, an OSError (a full disk) is raised as `failure(reason)` instead, the reason one
    line naming the file and the error ("cannot write x.csv (No space left on device)"), or
    its folder where that is missing (`require_folder`).

    `sidecar` (its path and data: the file's description) is written with it: both go to
    temporary files first, then the previous sidecar is moved aside, the file renamed into
    place (the previous sidecar put back if that fails) and the sidecar after it. A full disk
    then leaves both previous files as they were, and a kill at worst the new file without a
    sidecar, never beside the previous one's (which describes another result). A sidecar of
    data None is the previous file's to remove: the new file describes itself (a Parquet file
    written over an earlier CSV's name)."""
    with _write_lock(Path(path)):
        _write_atomic(path, data, failure, sidecar)


def _write_atomic(path, data: bytes, failure: Optional[Callable[[str], Exception]],
                  sidecar: Optional[Tuple[Path, Optional[bytes]]]):
    """`write_atomic`, its file's lock held."""
    writes_sidecar = sidecar is not None and sidecar[1] is not None
    targets = [(Path(path), data)] + ([(Path(sidecar[0]), sidecar[1])] if writes_sidecar else [])
    writer = f"{os.getpid()}-{threading.get_ident()}"
    temporaries = [target.with_name(f".{target.name}{TEMPORARY_MARK}{writer}")
                   for target, _ in targets]
    # where the previous sidecar waits while the file is renamed (named after the sidecar)
    aside = Path(sidecar[0]) if sidecar else Path(path)
    previous = aside.with_name(f".{aside.name}{TEMPORARY_MARK}{writer}.previous")
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
            if sidecar and os.path.lexists(sidecar[0]):
                os.replace(sidecar[0], previous)
            os.replace(temporaries[0], current)
        except BaseException:
            # Ctrl-C too, which Python raises after the system call in progress: the table's
            # temporary still there says its rename did not happen, and the previous table
            # keeps its sidecar; renamed, the new table stands without one
            if os.path.lexists(temporaries[0]) and os.path.lexists(previous):
                os.replace(previous, sidecar[0])
            raise
        if writes_sidecar:
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
