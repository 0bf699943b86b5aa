"""Provenance of a study's tables: what produced them, written as a JSON sidecar beside each.

The sidecar of `fig4c.csv` is `fig4c.csv.json`: the study and its command line, the package
version, git commit and dirty flag, the model (preset and every StarParams field) and solver
configuration, Taichi and Python versions, the machine (CPU model, cores, vector instruction
sets, cache sizes, GPU), the date and the wall seconds the study had run when it wrote the
table.
"""

from __future__ import annotations

import dataclasses
import json
import os
import platform
import shlex
import subprocess
import time
from pathlib import Path
from typing import Dict, Mapping, Optional, Sequence

from taichi_star.provenance import code_record, code_version

STARTED = time.monotonic()
"""When the study's process imported this module (the command line imports it first): a
sidecar's `elapsed_s` counts from here."""


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


def record(study: str, argv: Sequence[str], model: Optional[Mapping] = None,
           solver=None, extra: Optional[Mapping] = None) -> Dict[str, object]:
    """The provenance of one study run. `model`: the preset name and the base StarParams (or
    any description of the instances); `solver`: a SolverConfig (or a description). A table's
    sidecar adds `elapsed_s`, the wall seconds the study had run when it was written."""
    return {
        "study": study,
        "command": " ".join(["python -m studies", study, *map(shlex.quote, argv)]),
        **code_record(),
        "model": plain(model),
        "solver": plain(solver),
        "machine": machine(),
        **({"details": plain(extra)} if extra else {}),
    }


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
    return (json.dumps(provenance, indent=2, default=repr) + "\n").encode()
