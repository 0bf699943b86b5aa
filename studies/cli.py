"""What every study's command line shares: the flags, their validation, the output folder.

Shared flags (each study adds the ones it takes): `--out` (default a fresh
`runs/<study>/<timestamp>/`), `--quick` (a small fast run; never into results/), `--arch`,
`--no-progress`, `--preset paper|accurate` and `--set NAME=VALUE` (the model), `--dt`,
`--cycles`, `--workers N` (local worker processes) or `--scheduler tcp://HOST:PORT` (a Dask
cluster), `--retries`, `--chunk-size`, `--run-dir` and `--resume` (a resumable run store). Bad
input is a `StudyArgumentError` naming the flag, raised before any compute; `python -m studies`
prints it on one line and exits with 2.

A flag may have a different default under --quick: `parser.add_argument(..., quick=VALUE)`.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import datetime
import difflib
import io
import itertools
import logging
import math
import re
import sys
import tempfile
import typing
import warnings
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence

import numpy as np
import pandas as pd

from taichi_star import (COMPONENT_HEIGHTS, DIFFERENTIABLE_FIELDS, JACOBIANS,
                         PER_ACTUATOR_FIELDS, PRESETS, SOLVER_RANGES, SolverConfig, StarParams,
                         allowed_values, check_work, fewest_steps)
from taichi_star.batch import (DEFAULT_CHUNK_SIZE, DEFAULT_RETRIES, MAX_LOCAL_WORKERS,
                               MAX_RETRIES, executor_for, has_chunks, stored_chunk_size,
                               write_atomic)
from taichi_star.experiment import PAPER_GAITS
from taichi_star.extras import require
from taichi_star.gait import Gait, all_gaits
from taichi_star.metrics import MAX_GOAL_MM
from taichi_star.output import column_unit, column_units, parquet_bytes, read_provenance
from taichi_star.planner import MAX_DEFAULT_GOALS, check_drive, default_goals, path_frames
from taichi_star.provenance import table_stamp
from taichi_star.sensitivities import parse_directions
from taichi_star.timegrid import (LongWorkWarning, SteadySpeedWarning, steps_in,
                                  warn_long_work, weighted_nodes)

from . import provenance

QUICK_DURATION_S = 0.2
"""--quick: simulated time of every instance, s (instead of whole cycles)."""
QUICK_DT = 2e-3
"""--quick: time step, s, unless --dt is given."""
GPU_CHUNK_SIZE = 16384
QUICK_CHUNK_SIZE = 8
"""--quick: instances per chunk, the smallest engine capacity, so that quick runs of different
sizes share one compiled engine instead of compiling one per batch size."""
NAMES_AS_WRITTEN = {"keep_default_na": False, "na_values": [""]}
"""`pandas.read_csv` options that read a table's text as written, an empty cell alone missing: a
gait, a parameter or a candidate a user named "NA", "null" or "nan" stays that name (pandas'
defaults read them as NaN: an audit, 2026-12)."""
EXACT_SETTING_COLUMNS = ("dt_s",)
"""Float columns of a study's table, beside the parameters, that a reader compares with its
own setting and `Output.write_csv` so writes exactly: plan's --primitives holds a table to its
run's step (at 10 digits a step of 3.15/1100 s was refused as another: an audit)."""
RUNS_FOLDER = Path("runs")
"""Default parent of the output folders: runs/<study>/<timestamp>/ (git-ignored)."""
COMMITTED_RESULTS = (Path(__file__).resolve().parent.parent / "results").resolve()
"""The committed results, written only by full runs (`python -m studies reproduce`)."""
REPRODUCED_RESULTS = {
    "fig4c": [],
    "fig4c_accurate": ["fig4c", "--preset", "accurate", "--prefix", "fig4c_accurate"],
    "convergence": [],
    "gaits": ["--workers", "2"],
    "sweep": ["--alpha", "0.2:1.2:6", "--added-mass", "0,0.5,1,2",
              "--youngs-modulus", "2e6,5e6,1e7", "--workers", "2"],
    "calibrate": ["--preset", "accurate"],
    "crossval": ["calibrate", "--preset", "accurate", "--cross-validate"],
    "animate": [],
    "bench": ["--batch-sizes", "1,8,64,512,2048", "--repeats", "2"],
    "jacobians": [],
    "work_precision": [],
    "stability": ["--workers", "2"],
    "scaling": [],
    "sensitivity": ["--preset", "accurate"],
    "elasticities": ["--check", "alpha,drag_perpendicular,joint_radius,tip_radius,cylinder_drag,"
                     "cylinder_diameter,fluid_density,limb_stiffness_ratio,youngs_modulus,"
                     "added_mass_coeff,thickness"],
    "elasticities_accurate": ["elasticities", "--preset", "accurate", "--prefix",
                              "elasticities_accurate", "--check", "alpha,drag_perpendicular"],
}
"""The results `python -m studies reproduce` makes: result name -> the study's flags (the study
is the name unless the flags start with it)."""
MAX_INSTANCES = 1_000_000
"""The most instances one study run simulates (a sweep's product, a sensitivity's sample; a
range's points): about 100 times the sensitivity study's default 10,240, days of a 2-core CPU."""
MAX_REPEATS = 100
"""The most timed repeats or rounds of one measurement (bench's and simd's --repeats,
jacobians' --rounds): the best of a few is the figure, the committed results took at most 7."""
MAX_BATCH_SIZE = 2 ** 20
"""The most instances a benchmark builds one engine for (bench's batch sizes, env_bench's
robots): 16 times the largest batch the committed results measure (65,536 on an H200)."""

_UNSET = object()


class StudyArgumentError(ValueError):
    """A study argument is invalid; raised before any computation, naming the flag."""


class NotANumber(StudyArgumentError):
    """A value that should be a (finite) number or an integer is not one (`parse_number`,
    `parse_values`): the message can name the field's allowed range (`parse_field_values`)."""


class StudyOutputError(RuntimeError):
    """An output file cannot be written (a full disk, a folder gone); names the folder. The
    files written before are whole (each is written atomically)."""


# --------------------------------------------------------------------------- the parser

class OneLineParser(argparse.ArgumentParser):
    """A parser whose refusals (an unknown flag, a value of the wrong type, a choice not
    offered) are a StudyArgumentError, so that `python -m studies` prints them as one line
    with exit code 2, as it prints the studies' own checks, instead of argparse's usage block."""

    def error(self, message):
        raise StudyArgumentError(f"{message} (see --help)")


class StudyParser(OneLineParser):
    """The parser of one study, with the flags every study takes (--out, --quick, --arch,
    --no-progress). `add_argument(..., quick=VALUE)` gives a flag another default under
    --quick; both defaults are shown in its help, as any other flag's default is, each once:
    where the help already says the default, only the --quick one is added (docs/studies.md
    promises every flag's default)."""

    def __init__(self, study: str, description: str, archs=("cpu", "gpu")):
        super().__init__(prog=f"{provenance.program()} {study}", description=description,
                         allow_abbrev=False)
        # a value that starts with a minus and a digit is a value ("--alpha -1:1:3", a range,
        # was read as an unknown flag, "expected one argument", naming neither the value nor
        # its range: an audit, 2026-12); argparse's own rule takes plain numbers alone
        self._negative_number_matcher = re.compile(r"^-\.?\d")
        self.quick_defaults: Dict[str, tuple] = {}
        self.set_defaults(study=study)
        super().add_argument("--out", default=None, metavar="DIR",
                             help=f"output folder (default: a fresh {RUNS_FOLDER}/{study}/"
                                  f"<timestamp>/)")
        super().add_argument("--quick", action="store_true",
                             help="a small fast run (smoke test); never writes into results/")
        super().add_argument("--arch", choices=archs, default="cpu",
                             help="Taichi backend (default cpu)")
        super().add_argument("--no-progress", action="store_true", help="no progress bars")
        super().add_argument("--replace-committed", action="store_true",
                             help="let --out in the committed results/ replace the files "
                                  f"there (without it only `{provenance.program()} "
                                  f"reproduce`'s own runs do)")

    def add_argument(self, *names, quick=_UNSET, **kwargs):
        if quick is _UNSET:
            default = kwargs.get("default")
            if default not in (None, [], argparse.SUPPRESS) \
                    and kwargs.get("action") not in ("store_true", "store_false", "help") \
                    and "help" in kwargs and "default" not in kwargs["help"]:
                kwargs["help"] = (kwargs["help"] + f" (default {_shown(default)})").replace(
                    "%", "%%")
            return super().add_argument(*names, **kwargs)
        full = kwargs.pop("default", None)
        text = kwargs.get("help", "")
        # a help that states the default itself gets only the --quick one, said once
        stated = "" if "default" in text else f"default {_shown(full)}; "
        kwargs["help"] = (text + f" ({stated}--quick {_shown(quick)})").replace("%", "%%")
        action = super().add_argument(*names, default=None, **kwargs)
        self.quick_defaults[action.dest] = (full, quick)
        return action

    def parse_args(self, args=None, namespace=None):
        self.refuse_repeated_flags(sys.argv[1:] if args is None else list(args))
        parsed = super().parse_args(args, namespace)
        for dest, (full, quick) in self.quick_defaults.items():
            if getattr(parsed, dest) is None:
                setattr(parsed, dest, quick if parsed.quick else full)
        return parsed

    def refuse_repeated_flags(self, argv: Sequence[str]):
        """A flag that takes one value (not a repeatable one such as --set) given twice is
        refused: argparse keeps the last, and `--alpha 0.4,0.5 --alpha 0.8` swept 0.8 alone
        without a word (an audit, 2026-12)."""
        seen = set()
        for token in argv:
            if token == "--":
                break
            name = token.split("=", 1)[0]
            action = self._option_string_actions.get(name)
            if type(action) is not argparse._StoreAction:
                continue
            if action.dest in seen:
                self.error(f"{name} given twice (the second would replace the first): give it "
                           f"once")
            seen.add(action.dest)


def _shown(value) -> str:
    if isinstance(value, (list, tuple)):
        return " ".join(map(str, value))
    return "none" if value is None else str(value)


def add_model_flags(parser: StudyParser, fixed: Sequence[str] = (), preset: str = "paper"):
    """--preset (default `preset`: its help states it, as a default set afterwards would not)
    and --set; `fixed`: fields the study sets itself (refused in --set)."""
    parser.add_argument("--preset", choices=PRESETS, default=preset,
                        help="paper: the model as published (N = 193 nodes, implicit Euler at "
                             "1 ms); accurate: damping, series joints, shared ends, n_arc 48, "
                             "adaptive BDF2; identified: the model selection study's best model "
                             "(StarParams/SolverConfig.preset)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="change one StarParams field for every instance, e.g. --set "
                             "alpha=1.0 (repeatable); a per-actuator field takes its eight "
                             "values A1..A8, --set actuator_gains=1,1,0.5,1,1,1,1,1")
    parser.set_defaults(fixed_fields=tuple(fixed))


def add_dt_flag(parser: StudyParser, quick: float = QUICK_DT, jacobian: bool = True):
    """--dt and (with `jacobian`) --jacobian; `quick`: the step under --quick (a study whose
    instances must step whole cycles may take a coarser one). A study that sets the Jacobian
    mode itself, or times several, passes jacobian=False."""
    parser.add_argument("--dt", type=float, quick=quick,
                        help=f"time step, s, in (0, {SOLVER_RANGES['dt'][1]:g}] (none: the "
                             f"preset's)")
    if jacobian:
        parser.add_argument("--jacobian", choices=JACOBIANS, default=None,
                            help="Newton's Jacobian mode (default: the preset's); lagged keeps "
                                 "the factorisation from step to step: fixed steps about 2.5x "
                                 "as fast, each converged to newton_tol but not to Newton's bits")


def add_cycles_flag(parser: StudyParser, default: float = 3.0,
                    quick_s: Optional[float] = QUICK_DURATION_S):
    """--cycles (actuation cycles from rest per instance). `quick_s`: the seconds --quick
    simulates instead, a --cycles given with --quick then refused by `parse` (it was ignored
    without a word, an audit, 2026-12); None: --quick runs the cycles too."""
    if quick_s is None:
        parser.add_argument("--cycles", type=float, default=default,
                            help=f"actuation cycles from rest per instance (default {default:g})")
        return
    parser.add_argument("--cycles", type=float, default=None,
                        help=f"actuation cycles from rest per instance (default {default:g}; "
                             f"--quick simulates {quick_s:g} s instead)")
    parser.set_defaults(cycles_without_quick=default)


def add_execution_flags(parser: StudyParser, chunk_size: int = DEFAULT_CHUNK_SIZE):
    """--workers / --scheduler / --retries / --chunk-size."""
    parser.add_argument("--workers", type=int, default=None, metavar="N",
                        help=f"run the chunks on N local worker processes (at most "
                             f"{MAX_LOCAL_WORKERS}), each a single-threaded Taichi runtime "
                             f"(default: in this process)")
    parser.add_argument("--scheduler", default=None, metavar="tcp://HOST:PORT",
                        help="run the chunks on an existing Dask cluster (docs/studies.md, "
                             "the common flags)")
    parser.add_argument("--retries", type=int, default=DEFAULT_RETRIES,
                        help=f"extra tries of a chunk whose worker process died running it "
                             f"alone (--workers) or whose Dask task raised (--scheduler), at "
                             f"most {MAX_RETRIES} (default {DEFAULT_RETRIES})")
    parser.add_argument("--chunk-size", type=int, default=None,
                        help=f"instances per chunk: one simulate call, one task (default "
                             f"{chunk_size} cpu, {GPU_CHUNK_SIZE} gpu, fewer to give every "
                             f"worker about four)")
    parser.set_defaults(default_chunk_size=chunk_size)


def add_resume_flags(parser: StudyParser):
    """--run-dir and --resume: the run store of the finished chunks (`run_store`)."""
    parser.add_argument("--run-dir", default=None, metavar="DIR",
                        help="run store of the finished chunks (default <out>/chunks)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in the run store (needs --out or --run-dir): "
                             "skip its finished chunks (the run's definition must be the same)")


def parse(parser: StudyParser, argv) -> argparse.Namespace:
    """Parse and check the shared flags (StudyArgumentError naming the flag)."""
    args = parser.parse_args(argv)
    if hasattr(args, "cycles_without_quick"):
        if args.cycles is None:
            args.cycles = args.cycles_without_quick
        elif args.quick:
            check_positive(args.cycles, "--cycles")
            raise StudyArgumentError("--cycles: not with --quick, which simulates a short time "
                                     "from rest instead of the cycles (give one of them)")
    if hasattr(args, "cycles"):
        check_positive(args.cycles, "--cycles")
    if getattr(args, "dt", None) is not None:
        longest = SOLVER_RANGES["dt"][1]
        # both ends named (a zero step was told "> 0" alone, a huge one the range: an audit)
        if not (math.isfinite(args.dt) and 0 < args.dt <= longest):
            raise StudyArgumentError(f"--dt must be in (0, {longest:g}] s, got {args.dt!r}")
    if getattr(args, "workers", None) is not None:
        check_count(args.workers, "--workers", 1, MAX_LOCAL_WORKERS)
    if getattr(args, "chunk_size", None) is not None and args.chunk_size < 1:
        raise StudyArgumentError(f"--chunk-size must be >= 1, got {args.chunk_size}")
    if hasattr(args, "retries"):
        check_count(args.retries, "--retries", 0, MAX_RETRIES)
        if args.retries != DEFAULT_RETRIES and args.workers is None and args.scheduler is None:
            # taken without a word, and recorded as given (an audit, 2026-12)
            raise StudyArgumentError("--retries: only with --workers or --scheduler (a chunk "
                                     "run in this process is not tried again)")
    # gait_design's --redraw '' read the current folder (an audit, 2026-12)
    for flag in ("out", "run_dir", "redraw"):
        value = getattr(args, flag, None)
        if value is not None and not value.strip():
            raise StudyArgumentError(f"--{flag.replace('_', '-')}: an empty folder name (give "
                                     f"a folder, e.g. runs/mine)")
    if getattr(args, "run_dir", None) is not None:
        check_future_folder(Path(args.run_dir), args.quick, "--run-dir")
    if getattr(args, "prefix", None) is not None:
        check_file_name(args.prefix, "--prefix")
    if getattr(args, "resume", False) and args.out is None \
            and getattr(args, "run_dir", None) is None:
        # a study that keeps its finished work in --out itself has no --run-dir
        alternative = " or --run-dir" if hasattr(args, "run_dir") else ""
        raise StudyArgumentError(f"--resume: give --out (the folder of the run to continue)"
                                 f"{alternative}")
    if getattr(args, "workers", None) is not None and args.scheduler is not None:
        raise StudyArgumentError("--workers and --scheduler: give one (local worker processes "
                                 "or a Dask cluster), not both")
    if getattr(args, "scheduler", None) is not None:
        try:
            from taichi_star.batch.dask_cluster import check_address
        except ImportError:
            raise StudyArgumentError("--scheduler needs Dask: pip install "
                                     "'taichi_star[dask]'") from None
        try:
            check_address(args.scheduler)
        except ValueError as error:
            raise StudyArgumentError(f"--{error}") from None
    if args.arch != "cpu":
        from taichi_star.runtime import available_archs
        if args.arch not in available_archs():
            raise StudyArgumentError(f"--arch {args.arch}: no such backend on this machine; "
                                     f"available archs: {', '.join(available_archs())}")
    return args


def check_file_name(name: str, flag: str):
    """StudyArgumentError naming the flag unless `name` is a plain file name: not empty, no
    path separator, not "." or ".." (output names never leave the output folder)."""
    if not name or name in (".", "..") or "/" in name or "\\" in name or "\0" in name:
        raise StudyArgumentError(f"{flag}: {name!r} is not a file name (no folders, no '/', "
                                 f"'\\' or '..': files go into --out)")


def work_arch(args) -> Optional[str]:
    """The arch whose bound a study's work is held to (`check_work`'s `arch`): its --arch,
    this machine's cores on the CPU; None (the fastest machine measured) where a Dask
    --scheduler may spread it over several. The CLI held every study to one H100's bound, so
    that a CPU run of years started with a warning (an audit, 2026-12)."""
    return None if getattr(args, "scheduler", None) else getattr(args, "arch", None)


def check_steps(what: str, steps: float, batch=None, arch: Optional[str] = None,
                nodes: Optional[float] = None):
    """StudyArgumentError (one line) unless `steps` time steps per instance (what `what` says
    gave them, e.g. "--cycles 3 (9.45 s) at dt = 0.001 s") stay within the step counter and,
    with `batch` instances of robots of `nodes` nodes (None: the paper robot's), their
    robot-steps within what can finish on `arch` (`work_arch`; `check_work`, which also warns
    with an estimate when it is long)."""
    try:
        check_work(what, steps, batch, arch, nodes)
    except ValueError as error:
        raise StudyArgumentError(str(error)) from None


def check_robot_steps(what: str, robot_steps: float, arch: Optional[str] = None,
                      nodes: Optional[float] = None):
    """`check_steps` of a whole run's robot-steps, every batch together (what `what` says gave
    them), of robots of `nodes` nodes (`check_steps`): refused past what can finish on `arch`,
    estimated when long. A study whose batches each stay under the warning gives their sum
    here (a grid of 3.6e10 robot-steps started without a word: an audit, 2026-12)."""
    # as one-step instances: check_work counts round(steps) × batch, the sum exactly
    check_steps(what, 1, max(round(robot_steps), 1), arch, nodes)


def check_length(length: str, duration_s: float, step_s: float, step_name: str):
    """`check_steps` of a run of duration_s (s, what `length` says, e.g. "--cycles 3 (9.45
    s)") at steps of step_s (s, named `step_name`)."""
    check_steps(f"{length} at {step_name} {step_s:g} s", duration_s / step_s)


def in_checkout() -> bool:
    """Whether the studies run from a checkout of the repository (its pyproject.toml beside
    the committed results/), not from an installed package (a results/ folder a run made in
    site-packages does not make one)."""
    return (COMMITTED_RESULTS.parent / "pyproject.toml").is_file()


def committed_input(path, flag: str, made_by: str) -> str:
    """`path`, a table a flag names, unless it lies in the committed results/ (a flag's default)
    and is not there: an installed package holds no results/ (they come with a checkout of the
    repository), and such a study failed naming a file in site-packages (an audit, 2026-12).
    StudyArgumentError naming the flag and `made_by`, the study that makes the table."""
    resolved = Path(path).resolve()
    if not resolved.exists() and COMMITTED_RESULTS in resolved.parents and not in_checkout():
        raise StudyArgumentError(
            f"{flag} {path}: not here (the committed results/ come with a checkout of the "
            f"repository, not with an installed package): make one with `{provenance.program()} "
            f"{made_by}` and give its table as {flag}")
    return str(path)


def read_csv_file(path, flag: str, **options) -> pd.DataFrame:
    """The CSV file `path` that `flag` names, read by `pandas.read_csv(path, **options)`;
    StudyArgumentError naming the flag and the file, in one line, for a file that cannot be
    read (missing, a folder, no permission), is empty, is not text or is not CSV."""
    try:
        return pd.read_csv(path, **options)
    except pd.errors.EmptyDataError:
        raise StudyArgumentError(f"{flag} {path}: empty (not even a header row)") from None
    except UnicodeDecodeError as error:
        raise StudyArgumentError(f"{flag} {path}: not a UTF-8 text file (byte "
                                     f"{error.object[error.start]:#04x} at {error.start}: "
                                     f"{error.reason})") from None
    except (OSError, ValueError) as error:  # ValueError: pandas' ParserError among them
        # the tokenizer's message ends in a newline: the refusal stays one line
        reason = " ".join(str(error).split())
        raise StudyArgumentError(f"{flag} {path}: cannot read it ({reason})") from None


def read_table(path, flag: str, columns: Sequence[str], what: str) -> pd.DataFrame:
    """`read_csv_file`, with rows and at least `columns`; StudyArgumentError naming `flag`, the
    file and `what` the table should be ("a primitives table") otherwise."""
    table = read_csv_file(path, flag)
    missing = [column for column in columns if column not in table.columns]
    if table.empty or missing:
        raise StudyArgumentError(f"{flag} {path}: not {what} (needs rows with {sorted(columns)}; "
                                 f"{'no ' + ', '.join(missing) if missing else 'no rows'})")
    return table


def numeric_columns(table: pd.DataFrame, columns: Sequence[str], path, flag: str):
    """Turn `columns` of a table read from the file `path` into numbers, in place (an empty
    cell is NaN); StudyArgumentError naming `flag`, the file, the column, the row's gait and
    the value of the first cell that is no number."""
    for column in columns:
        values = pd.to_numeric(table[column], errors="coerce")
        wrong = values.isna() & table[column].notna()
        if wrong.any():
            row = table[wrong].iloc[0]
            raise StudyArgumentError(f"{flag} {path}: {column} of gait {row['gait']} is "
                                     f"{row[column]!r}, not a number")
        table[column] = values


def check_run(length: str, duration_s: float, config: SolverConfig,
              record_interval_s: float = 0.0, batch: Optional[int] = None,
              arch: Optional[str] = None, nodes: Optional[float] = None):
    """`check_steps` of a run of duration_s (s, what `length` says, e.g. "--cycles 3 +
    --glide-cycles 4 (22 s)") with this solver and records every record_interval_s (s; 0 =
    none), counted by the library's rule (`fewest_steps`: the fixed steps; adaptive ones at
    dt_max, or one per record where records are closer), so that the command line refuses what
    the library would, before any folder is made; and at least one fixed step. With `batch`
    (the instances of such runs a study makes) their robot-steps too: refused, or estimated
    when long (`check_work`), within what can finish on `arch` (`work_arch`), for robots of
    `nodes` nodes (None: the paper robot's)."""
    steps, bound = fewest_steps(config, duration_s, record_interval_s)
    check_steps(f"{length} at {bound}", steps, batch, arch, nodes)
    if not config.adaptive:
        check_one_step(length, duration_s, config.dt)


def check_one_step(length: str, duration_s: float, step_s: float, step_name: str = "dt ="):
    """StudyArgumentError unless a run of duration_s (s, what `length` says) is at least one
    fixed step of step_s (s, named `step_name`) once rounded to whole steps, as the library
    rounds it (`steps_in`)."""
    if steps_in(duration_s, step_s) < 1:
        raise StudyArgumentError(f"{length} is less than one step ({step_name} {step_s:g} s)")


def check_cycles(cycles: Mapping[str, int], period: float, config: SolverConfig):
    """`check_run` of a run of whole actuation cycles of `period` (s): the sum of the counts
    in `cycles`, each given by the flag it maps from ({"--cycles": 5, "--glide-cycles": 4})."""
    total = sum(cycles.values())
    named = " + ".join(f"{flag} {count}" for flag, count in cycles.items())
    check_run(f"{named} ({total * period:.3g} s)", total * period, config)


def robot_differences(path, base: StarParams, flag: str = "--primitives") -> tuple:
    """(the robot's parameters the sidecar of a table (given by `flag`) records, the fields
    other than gait in which `base` differs from them): a field the sidecar does not record
    came after the table, and the robot had its default (skipped until 2026-12, so --set
    wake_coupling=5 planned with another robot's steps). (None, []) where the sidecar is
    missing or records no robot, and a printed line says so (a table copied without its
    sidecar planned silently: an audit, 2026-12); one that cannot be read or no longer
    describes the table (`read_provenance`: its SHA-256 differs, the table edited since)
    records none either, said the same way."""
    sidecar = provenance.sidecar_path(path)
    not_compared = "the robot it was measured on is not compared with this run's"
    if not sidecar.is_file():
        print(f"{flag} {path}: no sidecar {sidecar.name} beside it; {not_compared}")
        return None, []
    try:
        recorded = read_provenance(path)["model"]["params"]
    except (KeyError, TypeError):  # a record of no robot
        recorded = None
    except (OSError, ValueError) as error:
        # a sidecar unreadable, damaged, or describing the table before an edit (gaits left
        # out, say): no record of the robot, as without a sidecar, and said
        reason = (f"{sidecar}: cannot read it ({error.strerror or error})"
                  if isinstance(error, OSError) else str(error))
        print(f"{flag} {reason}; {not_compared}")
        return None, []
    if not isinstance(recorded, dict):
        print(f"{flag} {path}: its sidecar records no robot; {not_compared}")
        return None, []
    recorded = {**provenance.plain(StarParams()), **recorded}
    own = provenance.plain(base)
    return recorded, [name for name in own if name != "gait" and recorded.get(name) != own[name]]


def add_goal_flags(parser: StudyParser, directions: int, far_mm: float,
                   quick_directions: Optional[int] = None):
    """--distance, --directions, --far and --tolerance: the goals a controller is driven to
    (`planner.default_goals`) and when one is reached (`goals_from_flags` checks them)."""
    parser.add_argument("--distance", type=float, default=50.0,
                        help="distance of the goals around the robot, mm (default 50)")
    quick = {} if quick_directions is None else {"quick": quick_directions}
    parser.add_argument("--directions", type=int, default=directions, **quick,
                        help=f"goals at --distance, equally spaced in direction (default "
                             f"{directions}, at most {MAX_DEFAULT_GOALS})")
    parser.add_argument("--far", type=float, default=far_mm,
                        help=f"distance of the goal straight behind, mm (default {far_mm:g}; 0: "
                             f"none)")
    parser.add_argument("--tolerance", type=float, default=5.0,
                        help="a goal is reached within this distance, mm (default 5)")


def goals_from_flags(args) -> np.ndarray:
    """The (G, 2) goals of `add_goal_flags`' flags, each refused naming it: --directions in [0,
    MAX_DEFAULT_GOALS], --distance in (0, MAX_GOAL_MM] mm and --far in [0, MAX_GOAL_MM] mm
    (1e308 ran every plan, then failed plotting: an audit), some goal, --tolerance > 0 and below
    the nearest goal (every such goal counts as reached before the robot moves)."""
    check_count(args.directions, "--directions", 0, MAX_DEFAULT_GOALS)
    check_positive(args.tolerance, "--tolerance")
    if not (math.isfinite(args.distance) and 0 < args.distance <= MAX_GOAL_MM):
        raise StudyArgumentError(f"--distance must be in (0, {MAX_GOAL_MM:g}] mm, got "
                                 f"{args.distance}")
    if not (math.isfinite(args.far) and 0 <= args.far <= MAX_GOAL_MM):
        raise StudyArgumentError(f"--far must be in [0, {MAX_GOAL_MM:g}] mm, got {args.far}")
    if args.directions == 0 and args.far == 0:
        raise StudyArgumentError("no goals: --directions 0 and --far 0")
    nearest_goal, flag = min((args.distance, "--distance") if args.directions else (math.inf, ""),
                             (args.far, "--far") if args.far else (math.inf, ""))
    if args.tolerance >= nearest_goal:
        raise StudyArgumentError(f"--tolerance must be below {flag} ({nearest_goal:g} mm), "
                                 f"got {args.tolerance!r}")
    return default_goals(args.distance, args.directions, args.far or None)


def driving(args) -> tuple:
    """(goals (G, 2) mm, the robot, the solver, path records per cycle) of a study that drives
    robots to goals (`add_goal_flags`, --max-cycles, --settle-cycles, the model and --dt),
    checked before any compute: the goals (`goals_from_flags`), the run's length named by its
    flags (`check_cycles`), then what `planner.check_drive` refuses (a period off the step
    grid), named --dt, --set period."""
    goals = goals_from_flags(args)
    base = base_params(args)
    config = solver(args)
    check_cycles({"--max-cycles": args.max_cycles, "--settle-cycles": args.settle_cycles},
                 base.period, config)
    frames = path_frames(base.period, config.dt)
    try:
        check_drive(goals, base, config, args.tolerance, args.max_cycles,
                    frames_per_cycle=frames, settle_cycles=args.settle_cycles)
    except ValueError as error:
        raise StudyArgumentError(f"--dt, --set period: {error}") from None
    return goals, base, config, frames


def tell_batch_work(args, config: SolverConfig, instances: int,
                    periods: Sequence[float] = (), replicas: int = 1,
                    nodes: Optional[float] = None) -> float:
    """Refuse (StudyArgumentError, with the estimate) a `run_batch` of `instances` robots, each
    run for `run_length(args)` with this solver, past what can finish on this machine
    (`check_robot_steps` on `work_arch`; not with a Dask --scheduler, whose machines share
    it), and warn of it (`LongWorkWarning`, with the hours) when long, before the study builds
    them: `run_batch` tells its estimate only once it has them, and a product near the
    studies' million instances took about two minutes to build (an audit, 2026-12); its
    chunks, each checked alone, started a sweep of 13 years with a warning (an audit,
    2026-12). `periods`: the actuation periods, s, that the instances share equally (a swept
    period's values; default: the model's).
    `replicas`: instances simulated per robot (sensitivities add two per parameter).
    `nodes`: the robots' nodes, their mean where the batch has several meshes (`mean_nodes`;
    None: the paper robot's).
    Returns the robot-steps (`fewest_steps` of each run, `run_batch`'s count). Run the batch
    within `batch_work_told()`, which keeps it from telling the same hours again."""
    periods = list(periods) or [base_params(args).period]
    durations = [duration_s(args, period) for period in periods]
    robot_steps = sum(fewest_steps(config, duration, 0.0)[0] for duration in durations) \
        * instances * replicas / len(periods)
    length = (f"--quick ({QUICK_DURATION_S:g} s)" if args.quick else
              f"--cycles {args.cycles:g} of {'each' if len(periods) > 1 else 'its'} period")
    if replicas > 1:
        length += f", each simulated {replicas} times over for its sensitivities"
    what = f"the batch of {instances:,} instances ({length})"
    if getattr(args, "scheduler", None):  # a cluster's machines share it: no one machine's bound
        warn_long_work(what, robot_steps, nodes)
    else:
        check_robot_steps(what, robot_steps, work_arch(args), nodes)
    return robot_steps


def mean_nodes(base: StarParams, axes: Mapping[str, Sequence]) -> float:
    """The mean nodes of the robots of a product of `axes` ({field: values}, `param_product`'s)
    on top of `base`: over the swept n_arc and n_limb, `base`'s where not swept (every
    combination of a product takes each mesh equally often, whatever else is swept)."""
    return weighted_nodes([(1, StarParams.node_count(n_arc, n_limb))
                           for n_arc in axes.get("n_arc", [base.n_arc])
                           for n_limb in axes.get("n_limb", [base.n_limb])])


@contextlib.contextmanager
def batch_work_told():
    """Within it, a `LongWorkWarning` says nothing: the study told the batch's estimate itself
    (`tell_batch_work`). The CLI's main thread alone runs a study, so the process's filters
    are the ones to change."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", LongWorkWarning)
        yield


@contextlib.contextmanager
def steady_speeds_unread():
    """Within it, a `SteadySpeedWarning` says nothing: around a study that does not read the
    steady speeds (`studies.STEADY_SPEED_STUDIES`)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SteadySpeedWarning)
        yield


def check_instances(instances: int, what: str):
    """StudyArgumentError unless a study's simulated instances (a fit's evaluations × the
    instances of one, a grid's points) are at most MAX_INSTANCES, the most a study runs: `what`
    says how they add up and names the flags (a billion generations, or a population of a
    billion, started and ran out of time or memory)."""
    if instances > MAX_INSTANCES:
        raise StudyArgumentError(f"{what}: {instances:,} instances, more than the "
                                 f"{MAX_INSTANCES:,} a study runs")


def check_count(value: int, flag: str, lowest: int, highest: int):
    """StudyArgumentError naming the flag unless lowest <= value <= highest (a count whose
    upper bound keeps the run finite: a study's MAX_ constant)."""
    if not lowest <= value <= highest:
        raise StudyArgumentError(f"{flag} must be in [{lowest}, {highest}], got {value}")


def check_positive(value: float, flag: str):
    """StudyArgumentError naming the flag unless value is a finite number > 0."""
    if not (math.isfinite(value) and value > 0):
        raise StudyArgumentError(f"{flag} must be > 0, got {value}")


# --------------------------------------------------------------------------- values

def parse_number(text: str, flag: str) -> float:
    """A finite number (StudyArgumentError naming the flag otherwise)."""
    try:
        value = float(text)
    except ValueError:
        raise NotANumber(f"{flag}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise NotANumber(f"{flag}: {text!r} is not a finite number")
    return value


def parse_range(text: str, flag: str = "value") -> List[float]:
    """"start:stop:n" -> n evenly spaced values from start to stop inclusive;
    "start:stop:n:log" -> n geometrically spaced values (start, stop > 0)."""
    parts = [p.strip() for p in text.split(":")]
    if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].lower() != "log"):
        raise StudyArgumentError(
            f"{flag}: malformed range {text!r}; expected start:stop:n or start:stop:n:log "
            f"(e.g. 0.2:1.2:11)")
    start, stop = parse_number(parts[0], flag), parse_number(parts[1], flag)
    try:
        count = int(parts[2])
    except ValueError:
        raise StudyArgumentError(f"{flag}: malformed range {text!r}: the number of points "
                                 f"{parts[2]!r} is not an integer") from None
    if count < 1:
        raise StudyArgumentError(f"{flag}: range {text!r} has {count} points; need at least 1")
    if count > MAX_INSTANCES:
        raise StudyArgumentError(f"{flag}: range {text!r} has {count} points; at most "
                                 f"{MAX_INSTANCES} (the most instances a study runs)")
    if count == 1 and start != stop:
        raise StudyArgumentError(f"{flag}: range {text!r} has one point but start != stop")
    if len(parts) == 4:
        if start <= 0 or stop <= 0:
            raise StudyArgumentError(f"{flag}: log range {text!r} needs start, stop > 0")
        return [float(v) for v in np.geomspace(start, stop, count)]
    return [float(v) for v in np.linspace(start, stop, count)]


def parse_values(text: str, flag: str = "value", kind: type = float,
                 repeats: bool = False) -> list:
    """A comma-separated list ("0,0.5,1", "contract,always") or, for numbers, a range
    ("0.2:1.2:11", "1e6:1e7:5:log"; of integers, one whose every value is an integer:
    "10:20:3"). StudyArgumentError naming `flag` when malformed or empty,
    or when a value is listed twice (it would only repeat the work) unless `repeats` (a list
    whose values may repeat: a per-actuator field's eight)."""
    if text is None or not str(text).strip():
        raise StudyArgumentError(f"{flag}: empty value list")
    text = str(text).strip()
    if kind is float and ":" in text:
        values = parse_range(text, flag)
    elif kind is int and ":" in text:
        values = integer_range(text, flag)
    else:
        items = [item.strip() for item in text.split(",")]
        if any(not item for item in items):
            raise StudyArgumentError(f"{flag}: malformed list {text!r} (an empty item)")
        if kind is float:
            values = [parse_number(item, flag) for item in items]
        elif kind is int:
            try:
                values = [int(item) for item in items]
            except ValueError as error:
                bad = str(error).rsplit(": ", 1)[-1]
                raise NotANumber(f"{flag}: {bad} is not an integer") from None
        else:
            values = items
    if not repeats and len(set(values)) < len(values):
        repeated = next(v for v, count in collections.Counter(values).items() if count > 1)
        raise StudyArgumentError(f"{flag}: {repeated!r} is listed twice in {text!r} (give each "
                                 f"value once)")
    return values


def integer_range(text: str, flag: str) -> List[int]:
    """A range of integers ("10:20:3" -> [10, 15, 20]; `parse_range`'s forms): each value
    must be an integer to within the range's rounding (1e-9, or 1e-12 of its magnitude where
    larger: a log range's values are off an integer by a few units of the last place), else
    StudyArgumentError naming the first that is not (1e-9 of the magnitude let 1000000001.5
    pass as an integer: an audit, 2026-12)."""
    values = parse_range(text, flag)
    for value in values:
        if abs(value - round(value)) > max(1e-9, 1e-12 * abs(value)):
            digits = max(6, len(str(int(abs(value)))) + 2)  # enough to show the fraction
            raise StudyArgumentError(f"{flag}: the range {text!r} gives {value:.{digits}g}, "
                                     f"not an integer (choose its ends and count so that "
                                     f"every value is one, or give a comma list)")
    return [int(round(value)) for value in values]


def parse_counts(text: str, flag: str, highest: Optional[int] = None) -> List[int]:
    """A comma list of integers >= 1 ("1,8,64") or a range of them ("64:4096:7:log",
    `integer_range`), each at most `highest` when given."""
    values = parse_values(text, flag, int)
    if any(v < 1 for v in values):
        raise StudyArgumentError(f"{flag}: every value must be >= 1, got {text!r}")
    if highest is not None and max(values) > highest:
        raise StudyArgumentError(f"{flag}: every value must be in [1, {highest}], got "
                                 f"{max(values)}")
    return values


def parse_choices(text: str, flag: str, choices: Sequence[str]) -> List[str]:
    """A comma list of names from `choices`, each once."""
    values = parse_values(text, flag, str)
    unknown = [v for v in values if v not in choices]
    if unknown:
        raise StudyArgumentError(f"{flag}: unknown value {unknown[0]!r}; choose from "
                                 f"{', '.join(choices)}")
    return values


HEIGHTS_IN_ALL = ("with", "without", "only")
"""What "all" of `sensitivity_parameters` does with the component heights."""


def sensitivity_parameters(text: str, flag: str, heights: str = "with") -> List[str]:
    """The parameters `flag` names for `simulate(sensitivities=...)`, one label each ("alpha",
    "actuator_gains[2]"; a per-actuator field stands for its eight, in actuator order): a comma
    list of names as `simulate` takes them, each once (an actuator by its Python index:
    actuator_gains[0] is A1's), or "all", every differentiable StarParams field
    (`DIFFERENTIABLE_FIELDS`, in its order). The component heights (`COMPONENT_HEIGHTS`) have a
    derivative only with the 2.5-D model on (> 0), so which of them "all" holds depends on the
    study's robot, and `heights` says it: "with" the other fields (elasticities: the user's
    model, whose heights at 0 it refuses after), "without" them (a robot with the heights off:
    sensitivity_check's paper robot, elasticities' default on such a model) or "only" them
    (sensitivity_check's one setting with the heights on, which checks them alone: every other
    field is checked in its other settings). A list is taken as it is, whatever `heights`.
    StudyArgumentError naming `flag` for an empty list or item or a name listed twice
    (`parse_values`), and for an unknown or non-differentiable name or an actuator named twice
    ("actuator_gains,actuator_gains[2]": `parse_directions`)."""
    if heights not in HEIGHTS_IN_ALL:
        raise ValueError(f"heights must be one of {HEIGHTS_IN_ALL}, got {heights!r}")
    if text.strip() == "all":
        names = [name for name in DIFFERENTIABLE_FIELDS if heights == "with"
                 or (name in COMPONENT_HEIGHTS) == (heights == "only")]
    else:
        names = parse_values(text, flag, str)
    try:
        return [direction.label for direction in parse_directions(names)]
    except ValueError as error:
        raise StudyArgumentError(f"{flag}: {error}") from None


def heights_in_all(base: StarParams) -> str:
    """`sensitivity_parameters`' `heights` for a study's model `base`: "with" where its
    component heights are set (> 0), else "without" (a derivative across the 2.5-D switch at 0
    is refused; the heights are all 0 or all set)."""
    return "with" if base.hub_height > 0 else "without"


def field_kind(name: str, flag: Optional[str] = None) -> type:
    """float, int or str: the type of a StarParams field (StudyArgumentError if unknown, naming
    `flag` when given and the closest fields)."""
    hints = typing.get_type_hints(StarParams)
    if name not in hints:
        close = difflib.get_close_matches(name, StarParams.field_names(), n=3)
        hint = f"did you mean {', '.join(close)}?" if close else \
            f"StarParams fields: {', '.join(StarParams.field_names())}"
        raise StudyArgumentError(f"{flag + ': ' if flag else ''}unknown parameter {name!r}; "
                                 f"{hint}")
    return hints[name]


def parse_assignment(text: str, flag: str):
    """"name=values" (e.g. "alpha=0.2:1.2:6"; --set takes one value, "alpha=0.8") -> (field
    name, list of values)."""
    if "=" not in text:
        example = "alpha=0.8" if flag == "--set" else "alpha=0.2:1.2:6"
        raise StudyArgumentError(f"{flag}: expected NAME=VALUE{'' if flag == '--set' else 'S'} "
                                 f"(e.g. {example}), got {text!r}")
    name, values = text.split("=", 1)
    name = name.strip().replace("-", "_")
    return name, parse_field_values(values, f"{flag} {name}", name, flag)


def parse_field_values(text: str, flag: str, name: str, unknown_flag: Optional[str] = None):
    """The values of StarParams field `name` in `text` (`parse_values`: a list or a range;
    StudyArgumentError naming `flag`, and the field's allowed range where it has one;
    `unknown_flag` names an unknown field)."""
    kind = field_kind(name, unknown_flag or flag)
    try:
        # a per-actuator field's values are its eight, A1..A8, which may be equal
        return parse_values(text, flag, kind, repeats=name in PER_ACTUATOR_FIELDS)
    except NotANumber as error:
        raise with_allowed_values(error, name) from None


def with_allowed_values(error: NotANumber, name: str) -> StudyArgumentError:
    """`error` with StarParams field `name`'s allowed values added (`allowed_values`: "'nan'
    is not a finite number" named none, where the API's message does: an audit, 2026-12)."""
    allowed = allowed_values(name)
    return StudyArgumentError(f"{error} ({name} must be "
                              f"{'in ' if allowed[0] in '[(' else ''}{allowed})")


GAITS_HELP = ("paper (the five Fig. 4c gaits), all (the 255 non-empty gaits) or a comma list "
              "such as A1,A1+A2")
"""The help of a --gaits flag that `resolve_gaits` reads (every form it accepts)."""


def resolve_gaits(text: str, flag: str = "--gaits", firing: bool = False) -> List[str]:
    """"paper" -> the five Fig. 4 gaits; "all" -> all 255 non-empty gaits; otherwise a comma
    list of gaits (validated, canonical names). `firing`: "none" refused, for a study of the
    speeds or their derivatives, which a robot that never fires has none of (its tables were
    all empty, with NumPy's warnings: an audit, 2026-12)."""
    if text is None or not text.strip():
        raise StudyArgumentError(f"{flag}: empty gait list")
    key = text.strip().lower()
    if key == "paper":
        return list(PAPER_GAITS)
    if key == "all":
        return all_gaits()
    gaits = []
    for item in text.split(","):
        try:
            gaits.append(Gait.parse(item.strip()).name)
        except ValueError as error:
            raise StudyArgumentError(f"{flag}: {error}") from None
    if len(set(gaits)) != len(gaits):
        raise StudyArgumentError(f"{flag}: a gait is listed twice: {text}")
    if firing and "none" in gaits:
        raise StudyArgumentError(f"{flag}: 'none' fires no actuator, and this study's speeds "
                                 f"and derivatives are of robots that swim: give gaits that "
                                 f"fire")
    return gaits


def paper_gaits_batch(size: int) -> List[StarParams]:
    """The plain call's batch: the five Fig. 4c gaits (`PAPER_GAITS`, default parameters)
    repeated in order to `size` instances."""
    return [StarParams(gait=PAPER_GAITS[i % len(PAPER_GAITS)]) for i in range(size)]


def check_axis_values(axes: Mapping[str, Sequence], base: StarParams = StarParams(),
                      flags: Mapping[str, str] = {}):
    """StudyArgumentError for an axis of StarParams field values (`param_product`'s) that
    names an unknown field, is empty or holds a value the field refuses on top of `base`,
    naming the flag that gave it (`flags`: {field: flag}; the field's name where none is
    given); each value alone, before any combination is built. A value that `base` refuses
    but `base` with some of the other axes at their first values takes (`smallest_fitting`:
    a tip radius beyond a swept joint radius, one of three swept component heights) is left
    to the combinations' check: it depends on them (each value was checked on `base` alone,
    and such sweeps were refused: an audit, 2026-12)."""
    for name in axes:
        field_kind(name, flags.get(name))
        if len(axes[name]) == 0:
            raise StudyArgumentError(f"empty product: parameter {name!r} has no values")
    for name in axes:
        others = {other: values[0] for other, values in axes.items() if other != name}
        for value in axes[name]:
            try:
                base.replace(**{name: value})
            except (ValueError, TypeError) as alone:
                if smallest_fitting(lambda chosen: base.replace(**chosen, **{name: value}),
                                    others) is None:
                    # the refusal with the other axes' first values where it is this field's
                    # (joint 0.02 m, tip 0.019 m: "in (0.02, 2]", not the base's joint radius)
                    try:
                        base.replace(**others, **{name: value})
                    except (ValueError, TypeError) as together:
                        error = together if str(together).startswith(name) else alone
                    raise StudyArgumentError(f"{flags.get(name, name)}: {error}") from None


def smallest_fitting(build, values: Mapping[str, object]) -> Optional[StarParams]:
    """`build` ({field: value} -> StarParams, raising ValueError or TypeError) of the smallest
    non-empty subset of `values` that it takes (fewest fields first, then in their order), or
    None where none does: the swept values a refused model needs, and only those (all of
    them, a provenance would record swept values as the base's, or a bad one among them
    blame a --set that fits the others: a review, 2026-12)."""
    names = list(values)
    for size in range(1, len(names) + 1):
        for subset in itertools.combinations(names, size):
            try:
                return build({name: values[name] for name in subset})
            except (ValueError, TypeError):
                continue
    return None


def param_product(axes: Mapping[str, Sequence], base: StarParams = StarParams(),
                  flags: Mapping[str, str] = {}) -> List[StarParams]:
    """Every combination of the given StarParams field values (the last axis varies fastest),
    on top of `base`; StudyArgumentError for an unknown field, an empty axis or an invalid
    value, naming the flag that gave the axis (`flags`: {field: flag}; the field's name where
    none is given): each value on its own first, then the combinations, where two fields'
    values may not fit together (a tip radius inside a swept joint radius)."""
    check_axis_values(axes, base, flags)
    names = list(axes)
    combos = []
    for values in itertools.product(*(axes[name] for name in names)):
        try:
            combos.append(base.replace(**dict(zip(names, values))))
        except (ValueError, TypeError) as error:
            given = ", ".join(flags.get(name, name) for name in names)
            raise StudyArgumentError(f"{given} together: {error}") from None
    return combos


# --------------------------------------------------------------------------- model, solver, runs

def base_params(args, axes: Mapping[str, Sequence] = {}) -> StarParams:
    """StarParams of --preset with the --set changes (StudyArgumentError naming --set). A
    study that sweeps fields gives its `axes` ({field: values}): --set changes that the
    preset refuses but some of the first swept values take (actuator delays beyond the
    preset's period, within a swept one) are then taken on top of the fewest of those values
    that do (`smallest_fitting`), which every combination of the sweep replaces."""
    overrides = {}
    for item in args.set:
        name, values = parse_assignment(item, "--set")
        if name in PER_ACTUATOR_FIELDS:
            # one value is the whole tuple, A1..A8 (StarParams checks the count and range)
            try:
                values = [tuple(parse_number(value, f"--set {name}") for value in values)]
            except NotANumber as error:
                raise with_allowed_values(error, name) from None
        if len(values) != 1:
            raise StudyArgumentError(f"--set {name}: give exactly one value, got {values}")
        if name in args.fixed_fields:
            raise StudyArgumentError(f"--set {name}: set by the {args.study} study itself")
        if name in overrides:
            raise StudyArgumentError(f"--set {name}: given twice")
        overrides[name] = values[0]
    try:
        return StarParams.preset(args.preset, **overrides)
    except (ValueError, TypeError) as error:
        fitting = smallest_fitting(
            lambda swept: StarParams.preset(args.preset, **swept, **overrides),
            {name: values[0] for name, values in axes.items()})
        if fitting is None:
            raise StudyArgumentError(f"--set: {error}") from None
        return fitting


def solver(args, periods: Sequence[float] = ()) -> SolverConfig:
    """SolverConfig of --preset with --dt and --jacobian (StudyArgumentError naming --dt); with
    the model flags, checks that the run's length (--cycles of the model's period, or
    --quick's) is at least one fixed step and at most MAX_STEPS_PER_INSTANCE steps (dt_max
    steps, the fewest, when adaptive) (StudyArgumentError naming the flags and the step).
    `periods`: the actuation periods, s, of a study that varies them (a sweep's values, the
    bounds of a --fit or --vary range: `range_periods`); --cycles of the longest must stay
    within the step limit and --cycles of the shortest make a step (default: the model's)."""
    try:
        changes = {} if args.dt is None else {"dt": args.dt}
        if getattr(args, "jacobian", None) is not None:
            changes["jacobian"] = args.jacobian
        config = SolverConfig.preset(getattr(args, "preset", "paper"), **changes)
    except ValueError as error:
        raise StudyArgumentError(f"--dt: {error}") from None
    if hasattr(args, "set") and (args.quick or getattr(args, "cycles", None) is not None):
        if args.quick:
            check_run(f"--quick ({QUICK_DURATION_S:g} s)", QUICK_DURATION_S, config)
        elif not periods:
            duration = args.cycles * base_params(args).period
            check_run(f"--cycles {args.cycles:g} ({duration:.3g} s)", duration, config)
        else:
            # each instance runs --cycles of its own period (run_batch's cycles): the longest
            # takes the most steps, the shortest the fewest
            longest, shortest = max(periods), min(periods)
            check_run(f"--cycles {args.cycles:g} of the longest period, {longest:g} s "
                      f"({args.cycles * longest:.3g} s)", args.cycles * longest, config)
            if not config.adaptive:
                check_one_step(f"--cycles {args.cycles:g} of the shortest period, "
                               f"{shortest:g} s ({args.cycles * shortest:.3g} s)",
                               args.cycles * shortest, config.dt)
    return config


def range_periods(ranges) -> List[float]:
    """The bounds, s, of the `period` axis among --fit or --vary ranges
    (`identify.ParameterRange`s), for `solver`'s periods; [] when none varies the period."""
    return [bound for axis in ranges if axis.name == "period" for bound in (axis.low, axis.high)]


def run_length(args) -> Dict[str, float]:
    """run_batch's length arguments: 0.2 s under --quick, else --cycles of each period."""
    return {"duration_s": QUICK_DURATION_S} if args.quick else {"cycles": args.cycles}


def duration_s(args, period: float) -> float:
    """Simulated time of a batch sharing one period, s: 0.2 s under --quick, else --cycles
    periods."""
    return QUICK_DURATION_S if args.quick else args.cycles * period


def chunk_size(args, n_instances: int, n_workers: int) -> int:
    """--chunk-size, else the study's default (larger on a GPU; QUICK_CHUNK_SIZE under
    --quick), cut so that every worker gets about four chunks."""
    if args.chunk_size is not None:
        return args.chunk_size
    size = GPU_CHUNK_SIZE if args.arch != "cpu" else args.default_chunk_size
    if args.quick:
        size = QUICK_CHUNK_SIZE
    if n_workers > 1:
        size = min(size, max(1, math.ceil(n_instances / (4 * n_workers))))
    return size


def run_store(args, out: "Output") -> Path:
    """The run store of --run-dir, else `<out>/chunks`; when resuming without --chunk-size,
    sets args.chunk_size to the stored run's own (its chunks must be cut the same way)."""
    run_dir = Path(args.run_dir) if args.run_dir is not None else out.folder / "chunks"
    out.run_store = run_dir
    if args.resume and args.chunk_size is None:
        args.chunk_size = stored_chunk_size(run_dir, flag="--run-dir")
    return run_dir


@contextlib.contextmanager
def executor(args, out: Output):
    """The executor --workers / --scheduler ask for (in process without either). An unreachable
    scheduler is a StudyArgumentError, and `out`'s folder is removed when this run made it and
    nothing was written into it yet (the address can only be tried, for up to its timeout,
    after the cheap checks have made the folder)."""
    with contextlib.ExitStack() as stack:
        try:
            chosen = stack.enter_context(executor_for(
                workers=args.workers, scheduler=args.scheduler, retries=args.retries))
        except ValueError as error:  # an unreachable scheduler
            out.remove_if_unused()
            raise StudyArgumentError(f"--{error}") from None
        yield chosen


# --------------------------------------------------------------------------- output

def written_provenance(csv_path) -> dict:
    """The provenance sidecar of a table this run wrote (`Output.write_csv`), {} without one;
    `read_provenance` checks that the table is still the one it describes. StudyOutputError
    naming the file where the sidecar cannot be read, is damaged or describes another table
    (another run writing into the same folder): a plot's title from it would describe a run
    that did not make the table."""
    sidecar = provenance.sidecar_path(csv_path)
    if not sidecar.exists():
        return {}
    try:
        return read_provenance(csv_path)
    except OSError as error:  # a folder, no permission
        raise StudyOutputError(f"{sidecar}: cannot read it ({error.strerror or error})") from None
    except ValueError as error:
        raise StudyOutputError(str(error)) from None


def run_settings(csv_path, mesh: bool = True) -> str:
    """"<preset> preset, n_arc N, <integrator> h = X ms" (adaptive: "tol = E m"; without the
    n_arc where the study varies it: `mesh` False) from the provenance sidecar of a table this
    run wrote (`written_provenance`), for plot titles; "" without one."""
    recorded = written_provenance(csv_path)
    model, solver = recorded.get("model") or {}, recorded.get("solver") or {}
    if not isinstance(model, dict) or "dt" not in solver:
        return ""
    parts = [f"{model['preset']} preset"] if "preset" in model else []
    if mesh and isinstance(model.get("params"), dict) and "n_arc" in model["params"]:
        parts.append(f"n_arc {model['params']['n_arc']}")
    stepping = (f"tol = {solver['error_tol']:g} m" if solver.get("adaptive")
                else f"h = {1e3 * solver['dt']:g} ms")
    parts.append(f"{solver.get('integrator', '')} {stepping}".strip())
    return ", ".join(parts)


def axis_label(column: str) -> str:
    """A plot axis label for a table column: its name with its unit, where it has one (a
    parameter column by its field name: "youngs_modulus (Pa)")."""
    unit = column_unit(column)
    fields = {column: name for name, column in StarParams.columns().items()}
    return f"{fields.get(column, column)} ({unit})" if unit not in ("", "1") else column


OPENED: List["Output"] = []
"""The study's output folders opened in this process, for `interrupted`."""


def interrupted() -> str:
    """After Ctrl-C: remove the output folders the run made and left empty; return what is
    kept, in one line ("the files written before are whole", and where a run store holds
    finished chunks, the command that continues it)."""
    for out in OPENED:
        out.remove_if_unused()
    stores = [out.run_store for out in OPENED
              if out.run_store is not None and has_chunks(out.run_store)]
    if stores:
        return (f"the finished chunks in {stores[0]} are kept: the same command with --resume "
                f"continues the run")
    records = [out.resume_records for out in OPENED if out.resume_records is not None
               and out.resume_records.is_dir() and any(
                   any(out.resume_records.rglob(pattern)) for pattern in ("*.json", "*.npz"))]
    if records:
        return (f"the finished work in {records[0]} is kept: the same command with --resume "
                f"continues the run")
    return "the files written before are whole"


class Output:
    """The output folder of one study run, checked before any compute: --out or a fresh
    runs/<study>/<timestamp>/. `write_csv` writes a table and its provenance sidecar (with the
    unit of every column whose unit its name tells: parameters and suffixes)."""

    def __init__(self, args, argv: Sequence[str], model=None, solver=None, extra=None):
        study = args.study
        self.folder = Path(args.out) if args.out is not None else _fresh_run_folder(study)
        self.made_folder = not self.folder.exists()
        check_folder_name(self.folder, args.quick, "--out")
        check_committed_folder(self.folder, study, argv,
                               getattr(args, "replace_committed", False))
        check_output_folder(self.folder, args.quick, "--out" if args.out is not None else None)
        self.provenance = provenance.record(study, list(argv), model=model, solver=solver,
                                            extra=extra)
        self.written: List[Path] = []
        self.run_store: Optional[Path] = None
        """The run store of the run's finished chunks, if it has one (`run_store`)."""
        self.resume_records: Optional[Path] = None
        """A folder of a study's own records of finished work (JSON files, or .npz
        checkpoints) that --resume reads back (model_select's done/, plan's resume/), if it
        keeps one: `interrupted` names it."""
        OPENED.append(self)

    def remove_if_unused(self):
        """Remove the folder if this run made it and it is still empty (a run refused after the
        folder was made); a folder that was there before is left as it was."""
        if self.made_folder and self.folder.is_dir() and not any(self.folder.iterdir()):
            self.folder.rmdir()

    def remove_earlier(self, *names: str):
        """Remove each file `names` names (relative to the folder) and a table's sidecar: this
        run has no rows for it (stability's paper table outside its grid, simd's assemblies
        in a run of the LU alone), and an earlier run's file left beside this run's would read
        as this run's (an audit, 2026-12). Removed rather than written empty: a CSV of no
        columns is no table pandas reads; no file means no rows. The file first, so that a
        kill between leaves at worst a sidecar of no table, never a table under another run's
        description. StudyOutputError naming the file where it cannot be removed."""
        for name in names:
            file = self.path(name)
            for path in (file, provenance.sidecar_path(file)):
                try:
                    path.unlink(missing_ok=True)
                except OSError as error:
                    raise StudyOutputError(f"--out {self.folder}: cannot remove the earlier "
                                           f"run's {path.name} ({error.strerror or error}); "
                                           f"the files written before are intact") from None

    def path(self, name: str) -> Path:
        """A file of this run, `name` relative to the folder ("gaits.png",
        "animations/A1.gif"), its folder created. ValueError for a name that would leave the
        folder (absolute, or with a "." or ".." part); StudyOutputError if the folder cannot be
        made."""
        parts = Path(name).parts
        if not parts or Path(name).is_absolute() or any(p in (".", "..") for p in parts) \
                or "\\" in name:
            raise ValueError(f"output name {name!r} would leave the output folder {self.folder}")
        path = self.folder / name
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise StudyOutputError(f"--out {self.folder}: cannot create {path.parent} "
                                   f"({error.strerror or error})") from None
        return path

    def write_csv(self, frame: pd.DataFrame, name: str, extra: Optional[Mapping] = None) -> Path:
        """Write a table (no index) and its JSON sidecar, both whole or not at all
        (`_write_described`): the parameter columns (`StarParams.columns()`) and the settings
        a reader compares with its own (`EXACT_SETTING_COLUMNS`) exact, each float the shortest
        text that reads back to it, so that `StarParams.from_row` of a row gives back the
        simulated robot (10 digits gave another: an audit); the other floats to 10
        significant digits, which keeps a rerun's table from differing in the last bits
        another CPU changes."""
        exact_columns = [column for column in (*StarParams.columns().values(),
                                               *EXACT_SETTING_COLUMNS)
                         if column in frame and frame[column].dtype.kind == "f"]
        # a float's text (str, as repr) is its shortest round-tripping one; NaN stays empty
        exact = frame.assign(**{column: frame[column].astype(str).where(frame[column].notna(), "")
                                for column in exact_columns})
        return self._write_described(
            self.path(name), exact.to_csv(index=False, float_format="%.10g").encode(), extra,
            frame)

    def write_parquet(self, frame: pd.DataFrame, name: str,
                      extra: Optional[Mapping] = None) -> Path:
        """Write a table as Parquet (typed columns, every float bit for bit) and its JSON
        sidecar; the provenance is also in the file's own metadata (key "taichi_star")."""
        return self._write_described(self.path(name), parquet_bytes(frame, self._details(extra)),
                                     extra, frame)

    def _details(self, extra: Optional[Mapping]) -> dict:
        details = {**self.provenance.get("details", {}), **(extra or {})}
        return {**self.provenance, **({"details": details} if details else {})}

    def _write_described(self, path: Path, data: bytes, extra: Optional[Mapping],
                         frame: pd.DataFrame) -> Path:
        """`write_atomic` of a table and its sidecar (the provenance, the study's wall time so
        far, the table's stamp and the unit of every column): a full disk leaves the previous
        pair, a kill at worst the new table without a sidecar, never beside the previous run's;
        a failure is a StudyOutputError naming the folder."""
        # the table's stamp: `read_provenance` refuses a table that is no longer the one
        # described (two runs writing into one folder could pair one's table with the other's
        # sidecar)
        sidecar = provenance.sidecar_text({**self._details(extra),
                                           "elapsed_s": provenance.elapsed_s(),
                                           **table_stamp(len(frame), data),
                                           "units": column_units(frame.columns)})
        write_atomic(path, data, sidecar=(provenance.sidecar_path(path), sidecar),
                     failure=lambda reason: StudyOutputError(
                         f"--out {self.folder}: {reason}; the files written before are intact"))
        self.wrote(path)
        return path

    def wrote(self, *paths) -> None:
        """Note files written otherwise (plots, notes); a file rewritten is listed once, within
        one call too."""
        for path in map(Path, paths):
            if path not in self.written:
                self.written.append(path)

    def report(self):
        print("\n".join(f"  wrote {p}" for p in self.written))


def _fresh_run_folder(study: str) -> Path:
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    folder = RUNS_FOLDER / study / stamp
    for suffix in itertools.count(1):
        if not folder.exists():
            return folder
        folder = RUNS_FOLDER / study / f"{stamp}-{suffix}"


def check_folder_name(folder: Path, quick: bool, flag: str):
    """StudyArgumentError naming `flag` where `folder` is a file, or --quick would write into the
    committed results/ or any folder in it; creates nothing."""
    resolved = folder.resolve()
    if quick and (resolved == COMMITTED_RESULTS or COMMITTED_RESULTS in resolved.parents):
        raise StudyArgumentError(f"{flag} {folder}: --quick runs never write into the committed "
                                 f"results/ (give another folder)")
    if folder.exists() and not folder.is_dir():
        raise StudyArgumentError(f"{flag} {folder}: exists and is not a folder")


RUN_PLACE_FLAGS = ("--out", "--no-progress", "--replace-committed")
"""Flags that say where a run writes and what it shows, not what it computes: left out where a
run's flags are compared with `reproduce`'s (`check_committed_folder`)."""


def flags_of_run(argv: Sequence[str]) -> List[str]:
    """A study's command-line flags without `RUN_PLACE_FLAGS` (and --out's value)."""
    flags, skip = [], False
    for token in argv:
        if skip:
            skip = False
        elif token == "--out":
            skip = True
        elif token.split("=", 1)[0] not in RUN_PLACE_FLAGS:
            flags.append(token)
    return flags


def check_committed_folder(folder: Path, study: str, argv: Sequence[str], replace: bool):
    """StudyArgumentError naming --out where a run would write into the committed results/
    (the folder or one in it) that already holds files, unless it is one of `python -m
    studies reproduce`'s runs (the same flags but `RUN_PLACE_FLAGS`, into results/ or a
    folder in it: its later studies write beside its first's) or is given
    --replace-committed: a small run there replaced the committed tables without a word (an
    audit, 2026-12). A new or empty folder in results/ (a new result) is taken."""
    resolved = folder.resolve()
    inside = resolved == COMMITTED_RESULTS or COMMITTED_RESULTS in resolved.parents
    if replace or not inside or not folder.is_dir() or not any(folder.iterdir()):
        return
    reproduced = [flags[1:] if flags and flags[0] == study else flags
                  for name, flags in REPRODUCED_RESULTS.items()
                  if (flags[0] if flags and not flags[0].startswith("-") else name) == study]
    flags = flags_of_run(argv)
    if flags in reproduced:
        return
    made_by = "; ".join(" ".join(each) or "no flags" for each in reproduced) or "none"
    raise StudyArgumentError(
        f"--out {folder}: holds committed results, which only `{provenance.program()} "
        f"reproduce` replaces (its runs of {study}: {made_by}); this run's flags "
        f"({' '.join(flags) or 'none'}) differ: give another --out, or --replace-committed to "
        f"replace them")


def check_future_folder(folder: Path, quick: bool, flag: str):
    """A folder that a run makes later (the run store of --run-dir, reproduce's --into) checked
    before any compute, creating nothing (StudyArgumentError naming `flag`): as
    `check_folder_name`, and the folder, or the nearest folder above it that exists,
    writable."""
    check_folder_name(folder, quick, flag)
    existing = next(path for path in (folder.absolute(), *folder.absolute().parents)
                    if path.exists())
    try:
        with tempfile.TemporaryFile(dir=existing):  # as root, os.access says yes to /proc
            pass
    except OSError as error:
        raise StudyArgumentError(f"{flag} {folder}: cannot write into {existing} "
                                 f"({error.strerror})") from None


def check_output_folder(folder: Path, quick: bool, flag: Optional[str] = "--out"):
    """Create the output folder or fail with a StudyArgumentError naming `flag` (--out; None
    for the default folder, named as such, under the current folder: it was named as an --out
    the user had not given, an audit, 2026-12): not a folder, cannot be created, not writable;
    --quick into the committed results/ or any folder in it."""
    check_folder_name(folder, quick, "--out")
    named = (f"{flag} {folder}" if flag else
             f"the default output folder {folder} (under {Path.cwd()}; --out DIR names another)")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise StudyArgumentError(f"{named}: cannot create it ({error.strerror})") from None
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as error:
        raise StudyArgumentError(f"{named}: not writable ({error.strerror})") from None


def use_agg():
    """Select the non-interactive Agg backend and return pyplot."""
    matplotlib = require("matplotlib", "plots")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def write_figure(fig, png_path, dpi: int = 130, **savefig) -> Path:
    """Write a figure as a PNG whole or not at all (`write_atomic`; matplotlib's `savefig`
    into the file itself left a truncated picture over the previous one on a full disk, and an
    error naming no file: an audit, 2026-12); StudyOutputError naming the file. `savefig`:
    matplotlib's other options (bbox_inches, ...). The PNG's text entries name the study,
    command, commit and dirty flag (`provenance.figure_metadata`). A figure that cannot be
    written is closed (pyplot keeps every open figure for the process: a notebook that catches
    the error would hold it for ever); one written stays open for its caller. Returns the
    path."""
    try:
        picture = io.BytesIO()
        fig.savefig(picture, format="png", dpi=dpi, metadata=provenance.figure_metadata(),
                    **savefig)
        write_atomic(png_path, picture.getvalue(), failure=lambda reason: StudyOutputError(
            f"{reason}; the files written before are intact"))
    except BaseException:
        use_agg().close(fig)
        raise
    return Path(png_path)


def save_figure(fig, png_path, dpi: int = 130) -> Path:
    """Lay out, write (`write_figure`) and close a figure; returns its path."""
    import matplotlib.pyplot as plt
    fig.tight_layout()
    write_figure(fig, png_path, dpi=dpi)
    plt.close(fig)
    return Path(png_path)


def configure_logging():
    """Show the batch layer's notes (resuming, a damaged chunk recomputed) on stderr: warnings
    and errors only, also from a library that sets its own loggers lower (Dask's distributed
    logs at INFO, among it a traceback of every connection closed when a cluster shuts down,
    and adds no handler of its own once this one is there)."""
    handler = logging.StreamHandler()
    handler.setLevel(logging.WARNING)
    logging.basicConfig(level=logging.WARNING, format="%(message)s", handlers=[handler])
