"""The run store: a folder holding one verified file per finished chunk and a manifest, so a
long batch can be resumed after a crash or a kill.

- `manifest.json`: the run's *definition* (instance count, SHA-256 of every instance's
  parameters that differ from their defaults, the chunk plan, duration or cycles, the solver's
  settings that differ from theirs, arch, records, steady window, the sensitivities where
  asked for: a field a later version adds
  with a default that changes nothing leaves a run resumable, `params.changed_fields`), the
  defaults themselves (a resume under changed ones is refused), its
  SHA-256, and for information the code version of its latest opening (`code`), every code
  version that made its chunks with the chunks each made (`code_versions`, brought up to date
  as each chunk is stored), and the times.
- `chunk_<index>.parquet`: one finished chunk's summary table, with sensitivities their
  columns too (`ChunkResult`; Parquet: a portable format that
  keeps every float bit and dtype; it needs pyarrow, the `io` extra, which `RunStore.open`
  asks for before any compute). Its schema metadata carries the definition's SHA-256, the
  chunk index, its instances and a SHA-256 of the table's content, and for a run with records
  the SHA-256 of its trajectory.
- `trajectory_<index>.parquet`: that chunk's trajectory (a run with records; with
  sensitivities, the records' derivatives as its columns), stamped the same
  way and written before the summary, whose file marks the chunk finished: a resumed run has
  every chunk's records, not only those it computed.
- Every file is written to a temporary name, flushed and renamed (`os.replace`): a kill leaves
  whole files or none.

On resume, a chunk file that is truncated, empty, undecodable in any way, from another run,
whose content does not match its checksum or that lacks the trajectory its run records is
reported (a warning on the `taichi_star.batch` logger), deleted and recomputed, never loaded;
one that is there but cannot be read (no permission, an I/O error) is a `RunStoreError` naming
it, and nothing is deleted. A damaged manifest is an
error (`RunStoreError`); a deleted one is not: resuming a folder of chunk files alone reuses the
chunks whose own stamp (the run definition's SHA-256, the chunk's instances) matches the run,
and refuses a folder holding a readable chunk of another run (without its manifest nothing says
that those results may go). A file that cannot be written (a full disk) or removed (a read-only
folder) is a `RunStoreError` naming it.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import logging
import os
import shutil
import socket
import weakref
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

try:
    import fcntl
except ImportError:  # Windows: the lock file's process decides alone
    fcntl = None

from ..actuation import CurvatureProfile
from ..checks import is_whole, warn_user
from ..extras import require
from ..params import SolverConfig, StarParams, changed_fields
from ..provenance import code_version, is_temporary, write_atomic
from .tasks import ChunkTask

MANIFEST = "manifest.json"
FORMAT = 3
"""Version of the store's layout (2: Parquet chunks with checksums; 3: a definition of the
parameters and solver settings that differ from their defaults; a format-2 run was defined by
every field, so a field added later made it unresumable: an audit, 2026-12)."""
METADATA_KEY = b"taichi_star.chunk"
VALUE_TYPES = {"CurvatureProfile": CurvatureProfile}
"""Value objects a summary column may hold; stored as JSON of their fields."""
REQUIRED_STAMP_KEYS = {"definition_sha256", "chunk", "members", "sha256"}
STAMP_KEYS = REQUIRED_STAMP_KEYS | {"value_types", "trajectory_sha256"}
"""The keys a chunk's metadata stamp may hold: all the required ones, value_types only where
the chunk has value-object columns, trajectory_sha256 only where it has a stored trajectory,
nothing else (a damaged key name is an unknown key, so it cannot drop what it says, e.g. the
value types, silently)."""

log = logging.getLogger("taichi_star.batch")


class RunStoreError(ValueError):
    """The run folder cannot be used as asked (another definition, an unfinished run without
    resume, not a run folder, a damaged manifest); one line, naming the folder."""


def _canonical(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=repr)


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode()).hexdigest()


def _changes(value) -> Dict:
    """`params.changed_fields` of a StarParams or SolverConfig, JSON-ready (a value object as
    the dict of its fields)."""
    return {name: dataclasses.asdict(field) if dataclasses.is_dataclass(field) else field
            for name, field in changed_fields(value).items()}


def run_definition(params: Sequence, tasks: Sequence[ChunkTask], chunk_size: int,
                   cycles: Optional[float], duration_s: Optional[float]) -> Dict:
    """What defines a run: a resumed run must match it exactly. JSON-ready."""
    first = tasks[0]
    return {
        "format": FORMAT,
        "n_instances": len(params),
        "params_sha256": _sha256("\n".join(_canonical(_changes(p)) for p in params)),
        "chunk_size": int(chunk_size),
        "n_chunks": len(tasks),
        "chunks_sha256": _sha256(_canonical([list(map(int, t.members)) for t in tasks])),
        "cycles": None if cycles is None else float(cycles),
        "duration_s": None if duration_s is None else float(duration_s),
        "solver": _changes(first.solver),
        "arch": first.arch,
        "record_interval_s": float(first.record_interval_s),
        "steady_from_cycle": int(first.steady_from_cycle),
        # only where asked for: the definitions (and SHA-256) of runs without them, stored
        # before run_batch took sensitivities, stay what they were
        **({"sensitivities": list(first.sensitivities)} if first.sensitivities else {}),
    }


def current_defaults() -> Dict:
    """The defaults of StarParams' and SolverConfig's fields, JSON-ready: a manifest records
    them beside its definition (which holds only what differs from them), so that a resume
    under a version that changed a default is refused (`changed_defaults`)."""
    return json.loads(_canonical({"params": dataclasses.asdict(StarParams()),
                                  "solver": dataclasses.asdict(SolverConfig())}))


def changed_defaults(recorded: Optional[Dict]) -> List[str]:
    """The fields, present then and now, whose default differs from the one a manifest
    recorded (`current_defaults`; None: a manifest from before they were): a run defined by
    its changes from the defaults would otherwise go on under other values without a word (a
    review, 2026-12). A field added since is not among them: the run's instances had its
    default, the only value there was."""
    if not isinstance(recorded, dict):
        return []
    now = current_defaults()
    return [f"the default {kind}.{name}: {value!r} -> {now[kind][name]!r}"
            for kind in ("params", "solver") if isinstance(recorded.get(kind), dict)
            for name, value in recorded[kind].items()
            if name in now[kind] and value != now[kind][name]]


def definition_differences(old: Dict, new: Dict) -> List[str]:
    """Human-readable differences between two definitions ("solver.dt: 0.002 -> 0.001"; a
    solver setting a definition leaves out is SolverConfig's default)."""
    unset = {"solver": dataclasses.asdict(SolverConfig())}
    differences = []
    for key in sorted(set(old) | set(new)):
        a, b = old.get(key), new.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            default = unset.get(key, {})
            differences += [f"{key}.{k}: {a.get(k, default.get(k))!r} -> "
                            f"{b.get(k, default.get(k))!r}"
                            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            differences.append("the instance parameters differ" if key == "params_sha256"
                               else f"{key}: {a!r} -> {b!r}")
    return differences


def table_checksum(frame: pd.DataFrame) -> str:
    """SHA-256 of a table's column names, dtypes and values (bitwise for numbers). Every
    non-numeric column counts as text whatever its pandas dtype: Parquet stores text as text, and
    a column of Python strings (object dtype) reads back as pandas' string dtype."""
    digest = hashlib.sha256()
    for name in frame.columns:
        column = frame[name]
        numeric = pd.api.types.is_numeric_dtype(column) or pd.api.types.is_bool_dtype(column)
        digest.update(f"{name}\0{column.dtype if numeric else 'text'}\0".encode())
        if numeric:
            digest.update(np.ascontiguousarray(column.to_numpy()).tobytes())
        else:
            digest.update(_canonical([None if pd.isna(v) else str(v) for v in column]).encode())
    return digest.hexdigest()


def _encode(frame: pd.DataFrame):
    """(frame with value-object columns as JSON text, {column: type name})."""
    encoded, types = frame.copy(), {}
    for name in frame.columns:
        first = frame[name].iloc[0] if len(frame) else None
        if frame[name].dtype == object and dataclasses.is_dataclass(first):
            types[name] = type(first).__name__
            encoded[name] = [_canonical(dataclasses.asdict(v)) for v in frame[name]]
    return encoded, types


def _decode(frame: pd.DataFrame, types: Dict[str, str]) -> pd.DataFrame:
    for name, type_name in types.items():
        frame[name] = pd.Series([VALUE_TYPES[type_name](**json.loads(v)) for v in frame[name]],
                                dtype=object, index=frame.index)
    return frame


def _readable_stamp(path: Path) -> Optional[Dict]:
    """The taichi_star stamp of a stored chunk file, None where it cannot be read (a damaged
    file: the verification recomputes it)."""
    _, pq = _parquet()
    try:
        raw = (pq.read_schema(path).metadata or {}).get(METADATA_KEY)
        stamp = json.loads(raw) if raw is not None else None
    except Exception:  # noqa: BLE001 -- pyarrow's errors for a damaged file vary
        return None
    return stamp if isinstance(stamp, dict) else None


def _parquet():
    """(pyarrow, pyarrow.parquet); ImportError naming the `io` extra where pyarrow is absent."""
    return require("pyarrow", "io"), require("pyarrow.parquet", "io")


_HOLDERS: Dict[Path, "weakref.ref[RunStore]"] = {}
"""The run folders this process's RunStores hold (`RunStore.lock`): a lock that names this
process but no living store of it is one a store dropped without releasing (taken over)."""
LOCK = ".run.lock"
"""The file that marks a run folder in use (the process and machine of the run that opened it),
made when a run opens the folder and removed when it ends: two runs in one folder had replaced
each other's manifest and chunks without a word (an audit, 2026-12)."""
CHUNK_FILES = "chunk_*.parquet"
"""The names of a run folder's chunk files (`RunStore.chunk_path`)."""
REPLACED = "replaced_run"
"""The subfolder where a finished run that a new run replaces (`open` without resume) waits,
its manifest and files, until the new run finishes (`finish`), then deleted: they were deleted
as the new run opened the folder, and a new run that then failed left neither (an audit,
2026-12)."""


def has_chunks(path) -> bool:
    """Whether the run folder `path` holds chunk files (finished chunks a resume keeps)."""
    return Path(path).is_dir() and any(Path(path).glob(CHUNK_FILES))


class RunStore:
    """A run folder for one run definition. `open` it (it returns the chunks already finished
    and verified), `write` each finished chunk, `read` them back, `finish` marks it complete.
    `flag` names the folder in error messages (a study's --run-dir)."""

    def __init__(self, path, definition: Dict, flag: str = "run_dir"):
        self.path = Path(path)
        self.definition = definition
        self.definition_sha256 = _sha256(_canonical(definition))
        self.flag = flag
        self.manifest: Dict = {}
        self.locked = False
        """Whether this run holds the folder (`LOCK`)."""
        self._close_lock = None
        """Closes the lock file held open (`lock`): by `release`, or when the store goes."""

    def chunk_path(self, index: int) -> Path:
        return self.path / f"chunk_{index:06d}.parquet"

    def trajectory_path(self, index: int) -> Path:
        return self.path / f"trajectory_{index:06d}.parquet"

    def _chunk_files(self) -> List[Path]:
        return sorted(self.path.glob(CHUNK_FILES))

    def _trajectory_files(self) -> List[Path]:
        return sorted(self.path.glob("trajectory_*.parquet"))

    def read_manifest(self) -> Optional[Dict]:
        """The folder's manifest, None if it has none; RunStoreError if it is damaged."""
        path = self.path / MANIFEST
        if not path.exists():
            return None
        try:
            raw = path.read_bytes()
        except OSError as error:  # there but not readable: not damage (an audit, 2026-12)
            raise _unreadable(path, error) from None
        try:
            manifest = json.loads(raw.decode())
            if not isinstance(manifest, dict) or not isinstance(manifest.get("definition"), dict):
                raise ValueError("no run definition in it")
            # valid JSON of the wrong kinds failed later with a TypeError ("resumed": 5) or
            # another library's error (a chunk size "8")
            if not isinstance(manifest.get("resumed", []), list):
                raise ValueError("its resumed entry is not a list")
            if not isinstance(manifest.get("complete", False), bool):
                raise ValueError("its complete entry is not true or false")
            versions = manifest.get("code_versions", [])
            if not isinstance(versions, list) or not all(
                    isinstance(entry, dict) and isinstance(entry.get("chunks"), list)
                    and all(is_whole(chunk) for chunk in entry["chunks"]) for entry in versions):
                raise ValueError("its code_versions entry is not a list of code versions, each "
                                 "with its chunks")
            size = manifest["definition"].get("chunk_size")
            if size is not None and not (is_whole(size) and size >= 1):
                raise ValueError(f"its chunk size {size!r} is not a whole number >= 1")
            # its definition as written beside its hash: an edit of the one (a changed
            # setting) was taken for another run, and the advice to delete the folder threw
            # away chunks whose stamps match this run (an audit, 2026-12)
            recorded = manifest.get("definition_sha256")
            if recorded is not None and recorded != _sha256(_canonical(manifest["definition"])):
                raise ValueError("its definition does not match its definition_sha256")
        except (OSError, UnicodeDecodeError, ValueError) as error:
            reason = str(error).splitlines()[0] if str(error) else type(error).__name__
            # "delete the folder" threw away finished chunks a resume without the manifest
            # keeps (an audit, 2026-12)
            raise RunStoreError(f"{self.flag} {self.path}: {MANIFEST} is damaged ({reason}); "
                                f"delete {MANIFEST} and resume with the run's own arguments "
                                f"(its chunk size too) to keep the chunks whose stamps match "
                                f"it, or delete the folder (or choose another {self.flag}) to "
                                f"start over") from None
        return manifest

    def open(self, tasks: Sequence[ChunkTask], resume: bool) -> List[int]:
        """Prepare the folder for this run; return the indices of the chunks already finished
        and verified (only when resuming). Raises RunStoreError, before any compute, for a
        folder that is not a run folder, holds another definition (resume) or an unfinished
        run (no resume); ImportError naming the `io` extra where pyarrow (the chunks' Parquet)
        is not installed."""
        _parquet()
        if self.path.exists() and not self.path.is_dir():
            raise RunStoreError(f"{self.flag} {self.path}: exists and is not a folder")
        self._refuse_entries_that_are_not_files()
        try:
            return self._open(tasks, resume)
        except BaseException:
            self.release()
            raise

    def _open(self, tasks: Sequence[ChunkTask], resume: bool) -> List[int]:
        """`open` of a folder that is one or is not there yet, its manifest read once this
        run holds the folder (`lock`)."""
        if self.path.is_dir():
            self.lock()
        old = self.read_manifest() if self.path.exists() else None
        version = code_version()
        now = datetime.datetime.now().isoformat(timespec="seconds")
        done: List[int] = []
        history: Dict = {}
        # a folder holding only a killed run's temporary files (its first manifest was being
        # written), or a run set aside by one killed before its first manifest, is empty
        if old is None and self.path.exists() and any(
                not is_temporary(entry) and entry.name not in (LOCK, REPLACED)
                for entry in self.path.iterdir()):
            done = self._orphan_chunks(tasks, resume)
        if old is not None:
            finished = self._chunk_files()
            if resume:
                if old["definition"].get("format") != self.definition.get("format"):
                    raise RunStoreError(
                        f"{self.flag} {self.path} holds a run in the store's format "
                        f"{old['definition'].get('format')!r}, this version's is "
                        f"{self.definition.get('format')!r} (a "
                        f"run is now defined by the settings that differ from their defaults); "
                        f"refusing to resume it: finish it with the version that started it, "
                        f"or delete the folder")
                differences = definition_differences(old["definition"], self.definition) \
                    + changed_defaults(old.get("defaults"))
                if differences:
                    raise RunStoreError(
                        f"{self.flag} {self.path} holds a run with another definition; refusing "
                        f"to resume it ({'; '.join(differences)}): use another {self.flag} or "
                        f"delete the folder")
                done = [task.index for task in tasks if self._verified(task)]
                if old.get("complete") and len(done) == len(tasks):
                    # a finished run read back: nothing to compute or record, so nothing is
                    # written (its manifest was, and a store on read-only media could not be
                    # read back: an audit, 2026-12)
                    self.manifest = {**old, "code_versions": makers_of_chunks(old, done)}
                    if any(maker["code"] != version for maker in self.code_versions()):
                        # its tables are the makers', which the result records (it named the
                        # reading code alone, without a word: an audit, 2026-12)
                        warn_user(f"reading back a run made with code "
                                  f"{[maker['code'] for maker in self.code_versions()]}; now "
                                  f"{version}: the result records the code that made its "
                                  f"chunks (code_versions)")
                    return done
                if old.get("code") != version:
                    # allowed (a typo fixed), but its table then mixes two codes' chunks: said
                    # to the user, and recorded in `code_versions` (a log line alone before,
                    # and the manifest kept only the last code: an audit)
                    warn_user(f"resuming a run started with code {old.get('code')}; now "
                              f"{version}: the manifest's code_versions records which chunks "
                              f"each made")
                history = {"created": old.get("created", now),
                           "resumed": list(old.get("resumed", [])) + [now]}
            elif not old.get("complete") and finished:
                raise RunStoreError(
                    f"{self.flag} {self.path} holds an unfinished run ({len(finished)} of "
                    f"{old['definition'].get('n_chunks')} chunks done): resume it, or delete the "
                    f"folder / choose another {self.flag} to start over")
            else:  # a finished (or empty) run is replaced by a fresh one
                if finished:  # said, not silent (an audit, 2026-12)
                    warn_user(f"{self.flag} {self.path} held a finished run ({len(finished)} "
                              f"chunk(s), created {old.get('created', 'at an unknown time')}): "
                              f"replaced by this one, kept in {REPLACED}/ until this one "
                              f"finishes (resume reads a finished run back)")
                    self._set_aside(finished + self._trajectory_files() + [self.path / MANIFEST])
                else:  # a run of no chunks: its stray records go
                    for path in self._trajectory_files():
                        self._remove(path)
        try:
            self.path.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise RunStoreError(f"{self.flag} {self.path}: cannot create it ({error.strerror})") \
                from None
        if not self.locked:  # a folder made just now
            self.lock()
        for stale in self.path.iterdir():  # left by a killed run
            if is_temporary(stale):
                self._remove(stale)
        self.manifest = {"definition": self.definition,
                         "definition_sha256": self.definition_sha256, "code": version,
                         "defaults": current_defaults(),
                         "code_versions": makers_of_chunks(old, done),
                         "created": now, "complete": False, **history}
        self._write_manifest()
        return done

    def code_versions(self) -> List[Dict]:
        """Every code version that made the stored chunks, each {"code": the version, "chunks":
        the indices it made} in the order they first ran (`makers_of_chunks`)."""
        return self.manifest.get("code_versions", [])

    def _refuse_entries_that_are_not_files(self):
        """RunStoreError naming the first of the store's names (its manifest, a chunk's or a
        trajectory's file) that is something other than a file (a folder): the store could
        neither read, replace nor delete it."""
        if not self.path.is_dir():
            return
        for path in [self.path / MANIFEST] + self._chunk_files() + self._trajectory_files():
            if path.exists() and not path.is_file():
                raise RunStoreError(f"{self.flag} {self.path}: {path.name} is not a file; "
                                    f"remove it or choose another {self.flag}")

    def _orphan_chunks(self, tasks: Sequence[ChunkTask], resume: bool) -> List[int]:
        """A non-empty folder without a manifest: when it holds only chunk files (its manifest
        was deleted) and `resume`, the indices of the chunks whose own stamp says they belong
        to this run (the others are recomputed); else RunStoreError saying what to do."""
        chunks = set(self._chunk_files())
        stored = chunks | set(self._trajectory_files())
        others = [p.name for p in self.path.iterdir()
                  if p not in stored and not p.name.startswith(".") and p.name != REPLACED]
        if others or not chunks:
            raise RunStoreError(f"{self.flag} {self.path}: not empty and has no {MANIFEST}; not "
                                f"a run folder (choose another {self.flag})")
        if not resume:
            raise RunStoreError(f"{self.flag} {self.path} holds chunk files but no {MANIFEST}: "
                                f"resume to reuse the chunks that belong to this run, or delete "
                                f"the folder / choose another {self.flag} to start over")
        indices = {task.index for task in tasks}
        for path in sorted(chunks):
            stamp = _readable_stamp(path)
            foreign = stamp is not None and (
                stamp.get("definition_sha256") != self.definition_sha256
                or stamp.get("chunk") not in indices)
            if foreign:
                # without a manifest the folder's own run is unknown: its chunks are another
                # run's results, deleted and replaced until 2026-12 (an audit)
                raise RunStoreError(
                    f"{self.flag} {self.path} has no {MANIFEST} and holds chunks of another run "
                    f"({path.name}: its definition differs from this run's); refusing to "
                    f"replace them: resume with that run's arguments, or delete the folder / "
                    f"choose another {self.flag}")
        log.warning("%s has no %s: reusing the chunks whose stamp matches this run", self.path,
                    MANIFEST)
        return [task.index for task in tasks if self._verified(task)]

    def _set_aside(self, paths: Sequence[Path]):
        """Move a finished run's files into REPLACED (a replacement of it interrupted before:
        the run set aside then is the one this finished run replaced, and goes)."""
        aside = self.path / REPLACED
        try:
            if aside.is_dir():
                shutil.rmtree(aside)
            aside.mkdir()
            for path in paths:
                os.replace(path, aside / path.name)
        except OSError as error:
            raise RunStoreError(f"{self.flag} {self.path}: cannot set the finished run aside in "
                                f"{REPLACED}/ ({error.strerror}); make the folder writable or "
                                f"choose another {self.flag}") from None

    def _remove(self, path: Path):
        """Delete one of the store's files; RunStoreError naming it where that fails (a
        read-only folder gave a raw OSError)."""
        try:
            path.unlink(missing_ok=True)
        except OSError as error:
            raise RunStoreError(f"{self.flag} {self.path}: cannot remove {path.name} "
                                f"({error.strerror}); make the folder writable or choose "
                                f"another {self.flag}") from None

    def _write_manifest(self):
        self._write(self.path / MANIFEST,
                    json.dumps(self.manifest, indent=2, sort_keys=True).encode())

    def _write(self, path: Path, data: bytes):
        """`write_atomic`, a failure (a full disk) a RunStoreError naming the folder: the files
        written before are whole, so the run can be resumed once there is room."""
        write_atomic(path, data, failure=lambda reason: RunStoreError(
            f"{self.flag} {self.path}: {reason}; the chunks stored before are kept: resume "
            f"once the folder can be written (room, permissions)"))

    def write(self, task: ChunkTask, summary: pd.DataFrame,
              trajectory: Optional[pd.DataFrame] = None) -> Path:
        """Store one finished chunk's summary and, where it has records, its trajectory (each
        atomically; the trajectory first, so that a chunk file means the chunk is whole)."""
        extra = {}
        if trajectory is not None and len(trajectory):
            extra["trajectory_sha256"] = self._write_table(self.trajectory_path(task.index),
                                                           task, trajectory)
        self._write_table(self.chunk_path(task.index), task, summary, extra)
        if self.manifest:  # opened: a store written without `open` has no manifest to keep
            self.manifest["code_versions"] = _with_chunks(self.code_versions(),
                                                          self.manifest["code"], [task.index])
            self._write_manifest()
        return self.chunk_path(task.index)

    def _write_table(self, path: Path, task: ChunkTask, frame: pd.DataFrame,
                     extra: Optional[Dict] = None) -> str:
        """Write `frame` as `task`'s stamped Parquet file at `path`; returns its checksum."""
        pa, pq = _parquet()
        encoded, types = _encode(frame)
        table = pa.Table.from_pandas(encoded, preserve_index=False)
        checksum = table_checksum(encoded)
        stamp = {"definition_sha256": self.definition_sha256, "chunk": task.index,
                 "members": list(map(int, task.members)), "sha256": checksum,
                 "value_types": types, **(extra or {})}
        table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                               METADATA_KEY: _canonical(stamp).encode()})
        sink = pa.BufferOutputStream()
        pq.write_table(table, sink)
        self._write(path, sink.getvalue().to_pybytes())
        return checksum

    def _load(self, task: "ChunkTask | StoredChunk"
              ) -> Tuple[pd.DataFrame, Optional[pd.DataFrame]]:
        """(the summary of the chunk `task` (a ChunkTask or StoredChunk), its trajectory or None
        where it stored none), the trajectory checked against the checksum the summary's stamp
        holds; ValueError saying why they cannot be trusted."""
        summary, stamp = self._load_table(self.chunk_path(task.index), task)
        if "trajectory_sha256" not in stamp:
            if task.record_interval_s > 0:
                # every run with records has one at its start at least: a chunk stored
                # without one (by a store before trajectories were kept) would drop its
                # instances' records from the result without a word (an audit, 2026-12)
                raise ValueError("stored without its trajectory, which this run records")
            return summary, None
        trajectory, trajectory_stamp = self._load_table(self.trajectory_path(task.index), task,
                                                        "its trajectory ")
        if trajectory_stamp["sha256"] != stamp["trajectory_sha256"]:
            raise ValueError("its trajectory is another one than the summary's")
        return summary, trajectory

    def _load_table(self, path: Path, task: "ChunkTask | StoredChunk", what: str = ""):
        """(table, stamp) of the file at `path` written for `task`; ValueError (its reason
        prefixed by `what`) saying why it cannot be trusted: missing or damaged. A file that
        is there but cannot be read (no permission, an I/O error) is no sign of damage: a
        RunStoreError naming it (such a file was deleted and recomputed: an audit, 2026-12)."""
        try:
            data = path.read_bytes()
        except FileNotFoundError as error:
            raise ValueError(f"{what}unreadable ({error.strerror})") from None
        except OSError as error:
            raise _unreadable(path, error) from None
        try:
            return self.decode_chunk(data, task)
        except ValueError as error:
            raise ValueError(f"{what}{error}") from None

    def decode_chunk(self, data: bytes, task: "ChunkTask | StoredChunk"):
        """(the table, its stamp) in the bytes of a file written for `task`; ValueError saying
        why it cannot be trusted. Any failure to decode is such an error, whatever raised it (a
        damaged file can make pyarrow or pandas fail in any way: a bit flip in the pandas
        metadata gives KeyError or TypeError from `to_pandas`); a missing pyarrow is not
        damage: its ImportError propagates."""
        pa, pq = _parquet()
        try:
            table = pq.read_table(pa.BufferReader(data))
        except Exception as error:  # noqa: BLE001 -- pyarrow's errors for a damaged file vary
            raise ValueError(f"unreadable ({str(error).splitlines()[0]})") from None
        try:
            raw = (table.schema.metadata or {}).get(METADATA_KEY)
            if raw is None:
                raise ValueError("no taichi_star chunk metadata")
            stamp = json.loads(raw)
            if not isinstance(stamp, dict) or not REQUIRED_STAMP_KEYS <= set(stamp) <= STAMP_KEYS:
                raise ValueError("its chunk metadata is malformed")
            if stamp["definition_sha256"] != self.definition_sha256:
                raise ValueError("from another run (its definition differs)")
            if stamp["chunk"] != task.index or stamp["members"] != list(map(int, task.members)):
                raise ValueError("holds another chunk's instances")
            frame = table.to_pandas()
            if table_checksum(frame) != stamp["sha256"]:
                raise ValueError("its content does not match its checksum")
            return _decode(frame, stamp.get("value_types", {})), stamp
        except ValueError:
            raise
        except Exception as error:  # noqa: BLE001 -- damage may surface as any exception
            reason = str(error).splitlines()[0] if str(error) else ""
            raise ValueError(f"undecodable ({type(error).__name__}: {reason})") from None

    def _verified(self, task: ChunkTask) -> bool:
        path = self.chunk_path(task.index)
        if not path.exists():
            return False
        try:
            self._load(task)
        except RunStoreError:
            raise  # not damage: nothing is deleted
        except ValueError as error:
            log.warning("%s: %s; recomputing it", path, error)
            self._remove(path)
            self._remove(self.trajectory_path(task.index))
            return False
        return True

    def read(self, task: ChunkTask) -> pd.DataFrame:
        """A stored chunk's summary, verified (RunStoreError if it changed since `open`)."""
        return self.read_chunk(task)[0]

    def read_chunk(self, task: ChunkTask) -> Tuple[pd.DataFrame, Optional[pd.DataFrame]]:
        """A stored chunk's (summary, trajectory), verified (RunStoreError if they changed
        since `open`, or if they cannot be read); the trajectory None where the run has no
        records."""
        try:
            return self._load(task)
        except RunStoreError:
            raise
        except ValueError as error:
            raise RunStoreError(f"{self.chunk_path(task.index)}: {error}") from None

    def lock(self):
        """Hold the folder for this run (`LOCK`, with this process and machine); RunStoreError
        naming the run that holds it where that run may still go on: a process of this machine
        that is alive (this one too: another call in it), or any process of another machine.
        A lock whose process on this machine has ended (a killed run's) is taken over. Where
        the system has it (POSIX) the lock file is also held open under `fcntl.flock` for the
        run's life, which the system lets go of when the process ends, so that of two runs
        taking over one ended run's lock at once only one gets it (each had read the ended
        holder before the other wrote, and both ran: an audit, 2026-12). A folder where no
        file can be made is not locked: no run can write into it either."""
        if self.locked:
            return
        path = self.path / LOCK
        while True:
            try:
                # without flock (Windows) the lock is made exclusively, its holder deciding
                descriptor = os.open(path, os.O_CREAT | os.O_RDWR
                                     | (os.O_EXCL if fcntl is None else 0), 0o644)
            except FileExistsError:
                holder = self._live_holder(path)
                if holder is not None:
                    raise self._in_use(holder, path) from None
                self._remove(path)
                continue
            except OSError:  # a read-only folder, or another user's lock file
                holder = self._live_holder(path) if path.exists() else None
                if holder is not None:
                    raise self._in_use(holder, path) from None
                if path.exists() and os.access(self.path, os.W_OK):
                    # an ended run's lock of another user, in a folder this run writes: taken
                    # over (left, the folder went unlocked: a review, 2026-12)
                    self._remove(path)
                    continue
                return
            if not _hold_exclusively(descriptor):
                os.close(descriptor)
                raise self._in_use(lock_holder(path) or "a run starting now", path)
            if not _same_file(descriptor, path):  # let go of and removed since it was opened
                os.close(descriptor)
                continue
            holder = self._live_holder(path) if fcntl is not None else None
            if holder is not None:
                os.close(descriptor)
                raise self._in_use(holder, path)
            os.ftruncate(descriptor, 0)
            os.write(descriptor, f"{os.getpid()} {socket.gethostname()}".encode())
            self._close_lock = weakref.finalize(self, os.close, descriptor)
            self.locked = True
            _HOLDERS[self.path.resolve()] = weakref.ref(self)
            return

    def _live_holder(self, path: Path) -> Optional[str]:
        """Who holds the lock at `path` and may still go on (`lock_holder`), None where no one
        does: its process has ended, or it is this process's and the run that took it is gone
        or is this one."""
        holder = lock_holder(path)
        if holder is not None and holder.endswith(OWN_PROCESS):
            held = _HOLDERS.get(self.path.resolve())
            holder = None if held is None or held() in (None, self) else holder
        return holder

    def _in_use(self, holder: str, path: Path) -> RunStoreError:
        return RunStoreError(f"{self.flag} {self.path} is in use by another run ({holder}); "
                             f"wait for it to end or choose another {self.flag} (if no run uses "
                             f"the folder, delete {path})")

    def release(self):
        """Let go of the folder (remove this run's `LOCK`, then close it: a run that opened it
        meanwhile finds it removed and opens the next); nothing where it holds none."""
        if self.locked:
            self.locked = False
            _HOLDERS.pop(self.path.resolve(), None)
            try:
                (self.path / LOCK).unlink(missing_ok=True)
            except OSError:  # the folder gone or read-only since: the next run takes it over
                pass
            self._close_lock()

    def finish(self):
        """Mark the run complete in its manifest and let go of the folder (`release`); a run
        read back (`open` of a finished run) writes nothing."""
        if self.manifest.get("complete"):
            self.release()
            return
        self.manifest["complete"] = True
        self.manifest["finished"] = datetime.datetime.now().isoformat(timespec="seconds")
        try:
            self._write_manifest()
            # the run this one replaced goes once this one is whole (left where that fails:
            # the next replacement removes it)
            shutil.rmtree(self.path / REPLACED, ignore_errors=True)
        finally:
            self.release()


OWN_PROCESS = " (this one: another call in it holds the folder)"


def _unreadable(path: Path, error: OSError) -> RunStoreError:
    """The error for a store's file that is there but cannot be read: one line naming it and
    the system's reason; nothing is deleted for it."""
    return RunStoreError(f"{path}: cannot be read ({error.strerror or error}); the run folder is "
                         f"left as it is: make the file readable, or choose another run folder")


def _hold_exclusively(descriptor: int) -> bool:
    """Whether this process now holds the open lock file `descriptor` exclusively
    (`fcntl.flock`, not waiting): False where another open file holds it; True also where the
    system or the file system has no such locks (the holder the file names decides alone)."""
    if fcntl is None:
        return True
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError:  # a file system without flock
        return True
    return True


def _same_file(descriptor: int, path: Path) -> bool:
    """Whether the open file `descriptor` is still the file at `path`."""
    try:
        return os.path.samestat(os.fstat(descriptor), os.stat(path))
    except FileNotFoundError:
        return False


def lock_holder(path: Path) -> Optional[str]:
    """Who holds the run folder lock at `path` ("process N on this machine", "process N on
    machine H"), None where its process on this machine has ended (or the lock names none: an
    empty file, a run that had not yet written itself in)."""
    try:
        process, _, machine = path.read_text().partition(" ")
    except OSError:
        return "a run whose lock cannot be read"
    if not process:
        return None
    if machine != socket.gethostname():
        return f"process {process} on machine {machine}"
    try:
        os.kill(int(process), 0)
    except (ValueError, ProcessLookupError):
        return None
    except PermissionError:  # alive, another user's
        pass
    return f"process {process} on this machine" + (OWN_PROCESS if int(process) == os.getpid()
                                                    else "")


def makers_of_chunks(manifest: Optional[Dict], chunks: Sequence[int]) -> List[Dict]:
    """The code versions that made `chunks` (those kept of a run: finished and verified), from
    its `manifest` (None: none was there): each of its `code_versions` entries with those of
    its chunks that are kept (a damaged chunk recomputed is no longer its maker's; an entry
    left without chunks is dropped); a kept chunk listed under none (a manifest from before
    code_versions, or a kill between storing the chunk and the manifest) under the manifest's
    `code`, the version that opened the run last (None without a manifest: unknown)."""
    kept, listed, makers = set(chunks), set(), []
    for entry in (manifest or {}).get("code_versions", []):
        made = sorted((kept & set(entry["chunks"])) - listed)
        listed.update(made)
        if made:
            makers.append({"code": entry.get("code"), "chunks": made})
    unlisted = sorted(kept - listed)
    return _with_chunks(makers, (manifest or {}).get("code"), unlisted) if unlisted else makers


def _with_chunks(makers: List[Dict], code: Optional[Dict], chunks: Sequence[int]) -> List[Dict]:
    """`makers` (`makers_of_chunks`) with `chunks` added to `code`'s entry, which is appended
    where it has none."""
    makers = [dict(entry) for entry in makers]
    for entry in makers:
        if entry["code"] == code:
            entry["chunks"] = sorted(set(entry["chunks"]) | set(chunks))
            return makers
    return makers + [{"code": code, "chunks": sorted(set(chunks))}]


@dataclasses.dataclass(frozen=True)
class StoredChunk:
    """Where a chunk of a run read back without its arguments (`read_stored`) belongs: its
    index, the positions in the batch of its instances (from its own stamp, verified with its
    content) and its run's record interval (s; 0: no records, else its trajectory must be
    stored)."""

    index: int
    members: Tuple[int, ...]
    record_interval_s: float


@dataclasses.dataclass
class StoredRun:
    """A run store read back without the arguments of its run (`read_stored`).

    `manifest`: its manifest (`definition`, `defaults`, `code_versions`, ...); `chunks`: every
    stored and verified chunk by index, (members, summary, trajectory or None); `unusable`:
    every other chunk of the run by index, with why (not stored, damaged, another run's)."""

    path: Path
    manifest: Dict
    chunks: Dict[int, Tuple[Tuple[int, ...], pd.DataFrame, Optional[pd.DataFrame]]]
    unusable: Dict[int, str]

    @property
    def definition(self) -> Dict:
        return self.manifest["definition"]

    def code_versions(self) -> List[Dict]:
        """The code versions that made the chunks read (`makers_of_chunks`)."""
        return makers_of_chunks(self.manifest, sorted(self.chunks))


READ_BACK_KEYS = {"n_instances": int, "n_chunks": int, "chunks_sha256": str, "solver": dict,
                  "arch": str, "record_interval_s": (int, float),
                  "steady_from_cycle": int, "chunk_size": int}
"""The entries of a run definition that reading a run back needs, with their JSON types."""


def read_stored(path, flag: str = "run_dir") -> StoredRun:
    """Every chunk of the run store in the folder `path`, read and verified without the run's
    arguments (its parameters, durations): each chunk file's stamp names its instances and is
    checked against the manifest's definition and the file's content, as a resume checks it.
    Nothing is written, locked or deleted: a store on read-only media, or one a run is still
    writing (its finished chunks are whole files), reads the same. A chunk not stored, damaged
    or of another run is listed in `unusable` with why. RunStoreError naming `flag` for a
    folder that is not a run store (no folder, no manifest, a damaged one, chunks whose
    instances are not its run's); ImportError naming the `io` extra without pyarrow."""
    _parquet()
    folder = Path(path)
    if not folder.is_dir():
        raise RunStoreError(f"{flag} {folder}: "
                            + ("is not a folder" if folder.exists() else "no such folder"))
    manifest = RunStore(folder, {}, flag=flag).read_manifest()
    if manifest is None:
        raise RunStoreError(f"{flag} {folder}: has no {MANIFEST}, so it is not a run store "
                            f"that can be read back alone (chunks whose manifest was lost are "
                            f"read back by run_batch(..., resume=True) with the run's own "
                            f"arguments)")
    definition = manifest["definition"]
    for key, kind in READ_BACK_KEYS.items():
        value = definition.get(key)
        if not isinstance(value, kind) or isinstance(value, bool):
            raise RunStoreError(f"{flag} {folder}: {MANIFEST} is damaged (its definition's "
                                f"{key} is {value!r}); the run cannot be read back alone")
    store = RunStore(folder, definition, flag=flag)
    chunks, unusable, owner = {}, {}, {}
    for index in range(definition["n_chunks"]):
        chunk_file = store.chunk_path(index)
        if not chunk_file.is_file():
            unusable[index] = "not stored"
            continue
        stamp = _readable_stamp(chunk_file) or {}
        members = stamp.get("members")
        if not (isinstance(members, list) and all(is_whole(m) for m in members)):
            unusable[index] = "unreadable (no chunk metadata naming its instances)"
            continue
        chunk = StoredChunk(index, tuple(int(m) for m in members),
                            float(definition["record_interval_s"]))
        try:
            summary, trajectory = store._load(chunk)
            if list(summary["instance"]) != list(chunk.members):
                raise ValueError("its table holds other instances than its stamp names")
        except RunStoreError:
            raise  # there but not readable: not damage
        except (ValueError, KeyError) as error:
            unusable[index] = str(error)
            continue
        for member in chunk.members:
            if not 0 <= member < definition["n_instances"] or member in owner:
                raise RunStoreError(f"{flag} {folder}: {chunk_file.name} holds instance "
                                    f"{member}, which is not one of its run's or is another "
                                    f"chunk's; the run cannot be read back")
            owner[member] = index
        chunks[index] = (chunk.members, summary, trajectory)
    if not unusable and _sha256(_canonical([list(chunks[i][0]) for i in sorted(chunks)])) \
            != definition["chunks_sha256"]:
        raise RunStoreError(f"{flag} {folder}: its chunks' instances are not the chunk plan "
                            f"its {MANIFEST} records; the run cannot be read back")
    return StoredRun(folder, manifest, chunks, unusable)


def stored_chunk_size(path, flag: str = "run_dir") -> Optional[int]:
    """The chunk size recorded in the manifest of the run in `path` (to resume it without
    repeating it), None when there is none; `flag` names `path` in a RunStoreError (a damaged
    manifest), as `RunStore`'s."""
    manifest = RunStore(path, {}, flag=flag).read_manifest() if Path(path).is_dir() else None
    return None if manifest is None else manifest["definition"].get("chunk_size")
