"""Provenance of a study's tables: what produced them, written as a JSON sidecar beside each.

The sidecar of `fig4c.csv` is `fig4c.csv.json`: the study and its command line, the package
version, git commit and dirty flag, the model (preset and every StarParams field) and solver
configuration, Taichi and Python versions, the machine (CPU model, cores, vector instruction
sets, cache sizes, GPU), the date and the wall seconds the study had run when it wrote the
table.
"""

from __future__ import annotations

import dataclasses
import os
import shlex
import sys
import time
from pathlib import Path
from typing import Dict, Mapping, Optional, Sequence

# the machine's description is the library's (its result files record it too)
from taichi_star.provenance import (code_record, code_version, machine, nvidia_smi,
                                    provenance_json)

from . import program

STARTED = time.monotonic()
"""When the study's process imported this module (the command line imports it first): a
sidecar's `elapsed_s` counts from here."""


def machine_columns(arch: str) -> Dict[str, object]:
    """Table columns naming the machine: machine (one line), cpu_model, cores, gpu and
    gpu_driver ("" on the CPU arch)."""
    facts = machine()
    gpu = ", ".join(facts["gpus"]) if arch != "cpu" else ""
    label = f"{facts['cpu_model']} ({facts['cores']} cores)" + (f" + {gpu}" if gpu else "")
    driver = ", ".join(nvidia_smi("driver_version")) if arch != "cpu" else ""
    return {"machine": label, "cpu_model": facts["cpu_model"], "cores": facts["cores"],
            "gpu": gpu, "gpu_driver": driver}


def short_commit() -> str:
    """Short hash of HEAD, "-dirty" when tracked files differ from it; "unknown" outside git."""
    code = code_version()
    if code["commit"] is None:
        return "unknown"
    return code["commit"][:7] + ("-dirty" if code["dirty"] else "")


def timing_columns(arch: str) -> Dict[str, object]:
    """The columns every timing table's rows carry beside their own batch, precision and
    preset: the machine's (`machine_columns`) and the code's commit (`short_commit`)."""
    return {**machine_columns(arch), "commit": short_commit()}


def shown_argv(argv: Sequence[str]) -> str:
    """The command-line words as one shell line of valid text: a word the locale could not
    decode (a non-ASCII path under LANG=C) holds lone surrogates, which no PNG text entry and
    no strict JSON reader takes (a figure failed with a traceback: an audit, 2026-12), its
    bytes shown as backslash escapes instead."""
    return shlex.join(os.fsencode(word).decode("utf-8", "backslashreplace") for word in argv)


def record(study: str, argv: Sequence[str], model: Optional[Mapping] = None,
           solver=None, extra: Optional[Mapping] = None) -> Dict[str, object]:
    """The provenance of one study run. `model`: the preset name and the base StarParams (or
    any description of the instances); `solver`: a SolverConfig (or a description). A table's
    sidecar adds `elapsed_s`, the wall seconds the study had run when it was written. The
    process's figures are attributed to the study of its latest record (`figure_metadata`)."""
    command = f"{program()} {study} {shown_argv(argv)}".rstrip()
    LATEST_STUDY.update(study=study, command=command)
    return {
        "study": study,
        "command": command,
        **code_record(),
        "model": plain(model),
        "solver": plain(solver),
        "machine": machine(),
        **({"details": plain(extra)} if extra else {}),
    }


LATEST_STUDY: Dict[str, str] = {}
"""The study and command line of this process's latest `record` (its figures name them)."""


def figure_metadata() -> Dict[str, str]:
    """The PNG text entries of a study's figure, as its tables' sidecars name them: study and
    command (of the process's latest `record`; the process's own command line where it made
    none), taichi_star_version, git_commit ("unknown" outside git), git_dirty ("true",
    "false", "unknown"), for a dirty checkout git_changes_sha256 and where no commit is known
    source_sha256 ("unknown" where a file could not be read). Inside the PNG, so that a figure
    copied away from its folder still says what made it (figures carried nothing: an audit); a
    few git calls, no machine survey."""
    code = code_version()
    dirty = {True: "true", False: "false"}.get(code["dirty"], "unknown")
    return {"study": LATEST_STUDY.get("study", ""),
            "command": LATEST_STUDY.get("command", shown_argv(sys.argv)),
            "taichi_star_version": code["version"], "git_commit": code["commit"] or "unknown",
            "git_dirty": dirty,
            **({"git_changes_sha256": code["changes_sha256"]} if "changes_sha256" in code
               else {}),
            **({"source_sha256": code["source_sha256"] or "unknown"} if "source_sha256" in code
               else {})}


def elapsed_s() -> float:
    """Wall seconds since the study started (`STARTED`), to 0.1 s."""
    return round(time.monotonic() - STARTED, 1)


def plain(value):
    """JSON-ready copy: dataclasses as dicts, tuples as lists."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return plain(dataclasses.asdict(value))
    if isinstance(value, Mapping):
        return {str(k): plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def sidecar_path(table_path) -> Path:
    return Path(f"{table_path}.json")


def sidecar_text(provenance: Mapping) -> bytes:
    """The content of a provenance sidecar (indented JSON)."""
    return (provenance_json(provenance, indent=2, default=repr) + "\n").encode()
