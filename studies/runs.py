"""Resumable runs: a run folder holding one file per finished chunk of instances and a manifest.

A long sweep is cut into chunks (`studies.common.plan_chunks`); every chunk's summary table is
written, as soon as the chunk is finished, to ``<run folder>/chunk_<index>.pkl`` through a
temporary file and an atomic ``os.replace``, so a crash or a SIGKILL leaves only whole chunk
files behind. ``manifest.json`` records the run's *definition* (a SHA-256 of the full list of
instance parameters, their count, the duration / cycles, the solver, the chunk size, ...) and,
for information, the code version, the arch and the time. Resuming a run skips the chunks whose
files exist and refuses a folder whose manifest has another definition; the final table is
assembled from the chunk files in input order.

Chunk files are pickled pandas DataFrames (exact floats and dtypes: a resumed run's table is
bitwise the uninterrupted one's); they are written and read only by this module.
"""

from __future__ import annotations

import dataclasses
import datetime
import hashlib
import json
import os
import subprocess
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import pandas as pd

MANIFEST = "manifest.json"
FORMAT = 1
IDENTITY_KEYS = ("format", "n_instances", "params_sha256", "chunk_size", "n_chunks", "chunks_sha256",
                 "cycles", "duration_s", "solver", "record_every", "steady_from_cycle")
"""Manifest entries that define a run: a resume must match them all."""


class RunFolderError(ValueError):
    """The run folder cannot be used as asked (another definition, an unfinished run without
    --resume, not a run folder)."""


def code_version() -> str:
    """`git rev-parse HEAD` of the source tree (with "+dirty" when taichi_star/ or studies/ have
    uncommitted changes), else the installed package version."""
    root = Path(__file__).resolve().parent.parent
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=root, capture_output=True,
                              text=True, timeout=10)
        if head.returncode == 0 and head.stdout.strip():
            dirty = subprocess.run(["git", "status", "--porcelain", "--", "taichi_star", "studies"],
                                   cwd=root, capture_output=True, text=True, timeout=10)
            suffix = "+dirty" if dirty.returncode == 0 and dirty.stdout.strip() else ""
            return head.stdout.strip() + suffix
    except (OSError, subprocess.SubprocessError):
        pass
    try:
        from importlib.metadata import version
        return "taichi_star " + version("taichi_star")
    except Exception:  # noqa: BLE001 - not installed: no better answer
        return "unknown"


def _canonical(value) -> str:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), default=repr)


def params_digest(params: Sequence) -> str:
    """SHA-256 of the full instance list (every field of every StarParams, in order)."""
    digest = hashlib.sha256()
    for p in params:
        digest.update(_canonical(dataclasses.asdict(p)).encode())
        digest.update(b"\n")
    return digest.hexdigest()


def build_manifest(params: Sequence, chunks: Sequence[Sequence[int]], chunk_size: int,
                   cycles: float, duration_s: Optional[float], solver, record_every,
                   steady_from_cycle: int, description: Optional[Dict] = None,
                   arch: str = "cpu") -> Dict:
    """The manifest of a run: its definition (IDENTITY_KEYS) plus informative entries."""
    return {
        "format": FORMAT,
        "n_instances": len(params),
        "params_sha256": params_digest(params),
        "chunk_size": int(chunk_size),
        "n_chunks": len(chunks),
        "chunks_sha256": hashlib.sha256(_canonical([list(map(int, c)) for c in chunks])
                                        .encode()).hexdigest(),
        "cycles": None if duration_s is not None else float(cycles),
        "duration_s": None if duration_s is None else float(duration_s),
        "solver": dataclasses.asdict(solver),
        "record_every": record_every,
        "steady_from_cycle": int(steady_from_cycle),
        # informative, not part of the definition
        "description": description or {},
        "code_version": code_version(),
        "arch": arch,
        "created": datetime.datetime.now().isoformat(timespec="seconds"),
        "complete": False,
    }


def manifest_differences(old: Dict, new: Dict) -> List[str]:
    """Human-readable differences between two manifests' definitions."""
    differences = []
    for key in IDENTITY_KEYS:
        a, b = old.get(key), new.get(key)
        if key == "solver" and isinstance(a, dict) and isinstance(b, dict):
            differences += [f"solver.{k}: {a.get(k)!r} -> {b.get(k)!r}"
                            for k in sorted(set(a) | set(b)) if a.get(k) != b.get(k)]
        elif a != b:
            if key == "params_sha256":
                differences.append("the instance parameters differ (sweep was "
                                   f"{_canonical(old.get('description', {}))}, now "
                                   f"{_canonical(new.get('description', {}))})")
            elif key != "chunks_sha256" or not differences:
                differences.append(f"{key}: {a!r} -> {b!r}")
    return differences


def _write_atomic(path: Path, write) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as handle:
            write(handle)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def read_manifest(folder) -> Optional[Dict]:
    path = Path(folder) / MANIFEST
    if not path.exists():
        return None
    with open(path) as handle:
        return json.load(handle)


class RunFolder:
    """A run folder: `open` it with the run's manifest, `done` chunks are skipped, `write` each
    finished chunk, `read` them back, `finish` marks the run complete."""

    def __init__(self, path, flag: str = "--run-dir"):
        self.path = Path(path)
        self.flag = flag
        self.manifest = None

    def chunk_path(self, index: int) -> Path:
        return self.path / f"chunk_{index:06d}.pkl"

    def _chunk_files(self):
        return sorted(self.path.glob("chunk_*.pkl"))

    def open(self, manifest: Dict, resume: bool) -> List[int]:
        """Prepare the folder for this run; return the indices of the chunks already finished
        (only when resuming). Raises RunFolderError, before any compute, when the folder holds
        another run's definition (resume) or an unfinished run (no resume)."""
        old = read_manifest(self.path) if self.path.exists() else None
        if self.path.exists() and old is None and any(self.path.iterdir()):
            raise RunFolderError(f"{self.flag} {self.path}: not empty and has no {MANIFEST}; "
                                 f"not a run folder (choose another {self.flag})")
        done = []
        if old is not None:
            differences = manifest_differences(old, manifest)
            finished = [int(p.stem.split("_")[1]) for p in self._chunk_files()]
            if resume:
                if differences:
                    raise RunFolderError(
                        f"--resume: {self.flag} {self.path} holds a run with another definition; "
                        f"refusing to mix them ({'; '.join(differences)}). Use another "
                        f"{self.flag} or delete the folder.")
                done = sorted(i for i in finished if i < manifest["n_chunks"])
                if old.get("code_version") != manifest["code_version"]:
                    print(f"note: resuming a run started with code {old.get('code_version')}; "
                          f"now {manifest['code_version']}")
                manifest = dict(manifest, created=old.get("created", manifest["created"]),
                                resumed=old.get("resumed", []) + [manifest["created"]],
                                code_versions=sorted(set(old.get("code_versions",
                                                                 [old.get("code_version")])
                                                         + [manifest["code_version"]])))
            elif not old.get("complete") and finished:
                raise RunFolderError(
                    f"{self.flag} {self.path} holds an unfinished run ({len(finished)} of "
                    f"{old.get('n_chunks')} chunks done); pass --resume to continue it, or "
                    f"delete the folder / choose another {self.flag} to start over")
            else:  # a finished (or empty) run is replaced by a fresh one
                for path in self._chunk_files():
                    path.unlink()
        self.path.mkdir(parents=True, exist_ok=True)
        for stale in self.path.glob(".chunk_*.tmp-*"):  # left by a killed run
            stale.unlink()
        self.manifest = manifest
        self._write_manifest()
        return done

    def _write_manifest(self):
        text = json.dumps(self.manifest, indent=2, sort_keys=True).encode()
        _write_atomic(self.path / MANIFEST, lambda handle: handle.write(text))

    def write(self, index: int, summary: pd.DataFrame) -> Path:
        path = self.chunk_path(index)
        _write_atomic(path, lambda handle: summary.to_pickle(handle))
        return path

    def read(self, index: int, members: Sequence[int]) -> pd.DataFrame:
        frame = pd.read_pickle(self.chunk_path(index))
        if frame["instance"].tolist() != list(members):
            raise RunFolderError(f"{self.chunk_path(index)}: holds instances other than its "
                                 f"chunk's; the run folder is corrupt (delete it)")
        return frame

    def finish(self):
        self.manifest["complete"] = True
        self.manifest["finished"] = datetime.datetime.now().isoformat(timespec="seconds")
        self._write_manifest()


def previous_chunk_size(folder) -> Optional[int]:
    """The chunk size of the run in `folder` (to resume it without repeating --chunk-size)."""
    manifest = read_manifest(folder) if Path(folder).exists() else None
    return None if manifest is None else manifest.get("chunk_size")
