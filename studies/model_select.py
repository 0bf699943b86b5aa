"""Model selection: candidate model forms fitted to the measured trajectories and ranked by how
well they predict what they were not fitted to.

    python -m studies model_select [--candidates CSV] [--only NAME,...] [--preset paper|accurate]
                                   [--set NAME=VALUE ...] [--gaits paper|A1,A1+A2,...]
                                   [--phases fitted|strokes] [--periods nominal|strokes]
                                   [--train-cycles 1:3] [--validate-cycles 4:6]
                                   [--popsize P] [--max-generations G] [--restarts R]
                                   [--fold-generations F] [--folds warm|cold]
                                   [--seed S] [--sigma0 0.25] [--dt S]
                                   [--start IDENTIFIED_CSV]
                                   [--refine-top K] [--refine-popsize P2]
                                   [--refine-generations G2]
                                   [--budget-hours 2] [--resume | --reassess]
                                   [--arch cpu|gpu] [--out DIR]
                                   [--quick] [--workers N | --scheduler tcp://HOST:PORT]

Candidates are data: a table (`--candidates`, default `studies/model_candidates.csv`) with one
row per model form: name, set (NAME=VALUE fields fixed on top of --preset/--set, space
separated), fit (NAME=LOW:HIGH[:log] axes, space separated; NAME[INDEX] for one element of a
tuple-valued field, e.g. actuator_gains[4]) and description. A candidate naming a field that
StarParams does not have is skipped with a note in the table (the model extensions are added
separately); `--only` picks candidates by name.

Each candidate is fitted by CMA-ES (`studies.identify.minimise_cmaes`: one batched `run_batch`
per generation, all points × all gaits; IPOP restarts) to the trajectory objective of
`taichi_star.identification` on the training cycles (`--train-cycles`, the paper's 1–3): per
gait, the simulated against the measured displacement-from-cycle-start curves, the trial's
pulse phase fitted as a nuisance, residuals in units of the measured spread across cycles,
plus a penalty on wrong-way travel. `--phases strokes` holds each trial's phase instead where
the simulated strokes meet the measured ones (`identification.stroke_aligned_phase`: the tracks
show when the pulses fire, docs: Results, "When the pulses fire"), in each window its own;
with it, `--periods strokes` fires each trial's model at the period its strokes' line gives
(3.171–3.181 s, where the file names say 3.15) and cuts its track into periods of that
length.
Then, per candidate:

- training error: the objective on the training cycles at the best point (re-simulated);
- validation error: the objective on `--validate-cycles` (4–6) with the training phases;
- leave-one-gait-out: for each gait, a fit on the others predicts the held-out gait. With
  `--folds warm` (the default) the fold starts at the full fit's best point with half its step
  and runs `--fold-generations` generations (0 skips the folds): cheap, but its start saw the
  held-out gait. With `--folds cold` each fold is a fit of its own from the search's start
  (the base model's values, or --start's) at the stage's whole budget (population,
  generations, restarts, step), about (gaits - 1) / gaits of the stage's fit per held-out gait:
  nothing in it saw the gait it predicts. An axis that only the held-out gait informs stays at
  its prior (the base model's value): an element INDEX of a per-actuator field (a tuple of 8)
  is informed only by gaits that fire actuator A<INDEX>;
- directions right (training and validation windows), the parameter count k (fitted axes plus
  one phase per gait with `--phases fitted`), χ² = Σ over the gaits of the squared residuals
  (curve samples and the direction residual, weighted as in the fit: as much as a whole
  curve), AIC = χ² + 2k and BIC = χ² + k ln n (n the number of curve samples).
  The curve samples of a trial are correlated (one path), so χ², AIC and BIC overstate the
  evidence; they rank, they do not test.

Two stages. The *screen* fits every candidate at the budget above (`--popsize`,
`--max-generations`); it is too small to converge a form of eight or more axes, so its rank is
partly the budget's. The *refine* stage fits the `--refine-top` best screened forms again, from
the same start, at a larger budget (`--refine-popsize`, `--refine-generations`) and assesses
them the same way. The start is the base model's values, or with `--start` those of an
earlier run's identified.csv (to continue a fit that stopped short of its optimum): the base
model stays the prior that a held-out fold keeps, so a fold never keeps a value fitted to the
gait it holds out. The ranking puts the refined forms first, in their own order, then every
screened form in its own: rank 1, the form the `identified` preset is read from, is the best
refined form (the best screened one with `--refine-top 0`).

Writes into `--out` (default a fresh `runs/model_select/<timestamp>/`), each table with its
provenance sidecar: `model_select.csv` (one row per candidate and stage, column `stage`:
refined forms first, each stage ranked by the held-out error (held-out gaits + cycles 4-6),
then BIC; skipped candidates last with their note), `model_select_parameters.csv` (the
identified values with a standard deviation from the final CMA-ES search distribution,
σ·√diag C mapped to the parameter: how tightly the search closed in on each axis, not a
posterior), `model_select_gaits.csv` (candidate × stage × gait × window: objective, phase,
speeds, direction), `model_select_folds.csv` (candidate × stage × held-out gait),
`fits/<candidate>.csv` (every evaluation, rewritten each generation; `fits/refine/` for the
refine stage), `model_select.png` (the ranking) and per candidate and stage Fig. 4c/4b at its
best point (`fig4c_<candidate>.*`, `fig4b_<candidate>.*`; `fig4c_<candidate>_refined.*`).

`--resume` (with `--out`): candidates whose rows are already in `done/` (`done/refine/`) with
the same definition (candidate, settings, model, solver) are read back, not refitted.
`--reassess` (with `--out`, the same flags as the run it assesses): their fits are read back
(`done/`: the best point, exact) and everything after the fit is done again with today's code:
both windows re-simulated and scored, the folds refitted (as --folds says: a fit assessed with
warm folds can be assessed again with cold ones), Fig. 4c/4b
redrawn; the note names the fit's evaluations and commit. For a change to the assessment that
leaves the fits as they were (eeefbb8, the strokes read over each window's own cycles); a fit
whose held phases were read another way (`STROKE_ALIGNMENT`) is made anew.

Cost: the study times its first generation, prints the estimate for the whole study (the
refine stage counted for the `--refine-top` largest forms) and the `--budget-hours` it is held
to; a candidate that would start after the budget has run out is skipped with a note.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from taichi_star import SolverConfig, StarParams, changed_fields, identification
from taichi_star.batch import run_batch
from taichi_star.gait import Gait
from taichi_star.output import read_provenance
from taichi_star.provenance import write_atomic
from taichi_star.timegrid import nearest_interval

from . import cli, figures, identify

DESCRIPTION = ("Model selection: candidate model forms fitted by CMA-ES to the measured "
               "trajectories (cycles 1-3), ranked by leave-one-gait-out and later-cycle error.")

CANDIDATES_CSV = Path(__file__).resolve().parent / "model_candidates.csv"
"""The default candidate table."""
QUICK_CANDIDATES = (
    {"name": "paper", "set": "", "fit": "alpha=0.2:1.5 cylinder_drag=1:100:log",
     "description": "the paper's model, alpha and C_c fitted"},
    {"name": "ramp", "set": "profile_closure=ramp", "fit": "alpha=0.2:1.5 cylinder_drag=1:100:log",
     "description": "the ramp closure, alpha and C_c fitted"},
)
"""--quick: two toy candidates (cma needs two axes at least)."""
QUICK_GAITS = "A1+A2,A1+A4"
QUICK_POPSIZE, QUICK_MAX_GENERATIONS, QUICK_FOLD_GENERATIONS = 4, 2, 1
DEFAULT_POPSIZE, DEFAULT_MAX_GENERATIONS, DEFAULT_FOLD_GENERATIONS = 6, 8, 2
DEFAULT_REFINE_TOP, DEFAULT_REFINE_POPSIZE, DEFAULT_REFINE_GENERATIONS = 6, 8, 16
"""The refine stage: the six best screened forms at 2.7x the screen's evaluations (8 x 16 +
16 x 16 = 384 with the restart, against 6 x 8 + 12 x 8 = 144). At the screen's budget a
10-axis form ended above the 8-axis form it contains (docs: Results, model selection)."""
QUICK_REFINE_TOP, QUICK_REFINE_POPSIZE, QUICK_REFINE_GENERATIONS = 1, 4, 3
QUICK_DT = 5e-3
"""--quick: time step, s (630 steps per 3.15-s cycle): the quick run checks the study's
pipeline, whose fits simulate whole cycles."""
PHASE_MODES = ("fitted", "strokes")
"""--phases: each trial's pulse phase fitted, or aligned on the measured strokes (`Setup`)."""
FOLD_MODES = ("warm", "cold")
"""--folds: each leave-one-gait-out fit started at the full fit's point, or fitted from the
search's start at the stage's budget (`FoldPlan`)."""
PERIOD_MODES = ("nominal", "strokes")
"""--periods: every trial at the nominal pulse period (3.15 s, the file names' 150 + 3000 ms),
or each at the period its strokes' line gives (`Setup.periods`; with --phases strokes)."""
STROKE_TAIL_CYCLES = 0.05
"""--phases strokes: cycles simulated past a window's last, 0.16 s of the paper's period: the
last period's strokes are read over `identification.STROKE_WINDOW_S` past its end, on records
of `identify.RECORD_INTERVAL_S`."""
STROKE_ALIGNMENT = "onsets"
"""How --phases strokes reads the strokes, part of a held candidate's definition so that a
resumed or reassessed run does not reuse results scored another way: "onsets", where each
period's stroke begins, the simulated ones over each window's own cycles (`identification.
strokes`, since 2026-12-05). Results stored before read each period's farthest move instead
("window", over each window's cycles, since eeefbb8; before it, no key, over the whole run):
their phases were held elsewhere, and their fits are made anew."""
STAGES = ("refine", "screen")
"""The stages in ranking order: a refined form above every screened one."""
PER_ACTUATOR = 8
"""A tuple-valued field of this length holds one value per actuator (A1..A8)."""
RESULT_COLUMNS = ["rank", "stage", "candidate", "status", "note", "n_fitted", "n_parameters",
                  "train_objective", "validate_objective", "logo_objective",
                  "held_out_objective", "logo_directions_right", "logo_within_35pct", "n_folds",
                  "train_directions_right", "validate_directions_right", "n_gaits", "chi2",
                  "n_samples", "aic", "bic", "n_evaluations", "fit_time_s", "fit", "set",
                  "description", "definition"]
"""Columns of model_select.csv. logo_within_35pct: held-out gaits in the right direction with
a speed within ±35 % of the measured one over the training window. held_out_objective: the
error on what the fit did not see, the held-out gaits (logo_objective) plus the later cycles
(validate_objective), or the later cycles alone where there are no folds (--fold-generations
0, one gait); the rank follows it within a stage (`STAGES`)."""


# --------------------------------------------------------------------------- candidates

@dataclasses.dataclass(frozen=True)
class Candidate:
    """One model form: fields fixed on top of the base model and axes fitted."""
    name: str
    set: str
    fit: str
    description: str = ""

    def field_names(self) -> List[str]:
        """The fields the candidate sets or fits, each once, in order."""
        return list(dict.fromkeys(item.split("=", 1)[0].split("[", 1)[0].strip().replace("-", "_")
                                  for item in (self.set.split() + self.fit.split())))

    def missing_fields(self) -> List[str]:
        """Fields the candidate names that StarParams does not have."""
        known = set(StarParams.field_names())
        return [name for name in self.field_names() if name not in known]

    def model(self, base: StarParams) -> StarParams:
        """The base model with the candidate's fixed fields (StudyArgumentError naming the
        candidate for a bad value)."""
        changes = {}
        for item in self.set.split():
            name, values = cli.parse_assignment(item, f"candidate {self.name}: set")
            if len(values) != 1:
                raise cli.StudyArgumentError(f"candidate {self.name}: set {name}: give one value")
            changes[name] = values[0]
        try:
            return base.replace(**changes)
        except (ValueError, TypeError) as error:
            raise cli.StudyArgumentError(f"candidate {self.name}: {error}") from None

    def skipped(self, note: str) -> dict:
        """The study's row of this candidate, skipped before any compute for `note`."""
        return {"candidate": self.name, "status": "skipped", "note": note, "fit": self.fit,
                "set": self.set, "description": self.description}

    def box(self, base: StarParams) -> List[identify.ParameterRange]:
        """The fitted axes, checked on the candidate's model."""
        box = [identify.parse_range_spec(text, f"candidate {self.name}: fit")
               for text in self.fit.split()]
        if len(box) < 2:
            # cma's sampler is undefined in one dimension: it failed after the first
            # generation with a traceback (an audit, 2026-12)
            raise cli.StudyArgumentError(f"candidate {self.name}: fit {self.fit!r}: CMA-ES "
                                         f"needs two axes at least, got {len(box)} (fit a second"
                                         f" one, or set this one)")
        identify.check_box(box, self.model(base), f"candidate {self.name}: fit")
        return box


def read_candidates(path) -> List[Candidate]:
    """The candidate table (columns name, set, fit, description); StudyArgumentError naming
    --candidates for a file that cannot be read (`cli.read_csv_file`: missing, empty, not
    text), a missing column or name, or a name given twice."""
    table = cli.read_csv_file(path, "--candidates", dtype=str, keep_default_na=False)
    missing = {"name", "set", "fit"} - set(table.columns)
    if missing:
        raise cli.StudyArgumentError(f"--candidates {path}: no column(s) "
                                     f"{', '.join(sorted(missing))}")
    candidates = [Candidate(row["name"].strip(), row["set"].strip(), row["fit"].strip(),
                            row.get("description", "").strip()) for _, row in table.iterrows()]
    names = [c.name for c in candidates]
    for name in names:
        if not name:
            raise cli.StudyArgumentError(f"--candidates {path}: a row has no name")
        if names.count(name) > 1:
            raise cli.StudyArgumentError(f"--candidates {path}: {name} is listed twice")
    return candidates


def informed_axes(box: Sequence[identify.ParameterRange], base: StarParams,
                  gaits: Sequence[str]) -> List[bool]:
    """Per axis: do the gaits inform it? An element INDEX of a per-actuator field (a tuple of
    `PER_ACTUATOR` values) only if some gait fires actuator A<INDEX>; every other axis always."""
    fired = np.zeros(PER_ACTUATOR, dtype=bool)
    for gait in gaits:
        fired |= Gait.parse(gait).mask.astype(bool)
    informed = []
    for spec in box:
        per_actuator = (spec.index is not None
                        and len(getattr(base, spec.name)) == PER_ACTUATOR)
        informed.append(bool(fired[spec.index - 1]) if per_actuator else True)
    return informed


# --------------------------------------------------------------------------- evaluation

@dataclasses.dataclass(frozen=True)
class FoldPlan:
    """How the leave-one-gait-out folds are fitted (`leave_one_gait_out`): `generations`
    (--fold-generations; 0: no folds) and `mode` (--folds, `FOLD_MODES`): "warm", each fold
    from the full fit's best point with half its step, `generations` generations, no restart
    (cheap, but its start saw the held-out gait); "cold", each fold a fit of its own from the
    search's start at the stage's whole budget (nothing in it saw the gait it predicts)."""
    generations: int = DEFAULT_FOLD_GENERATIONS
    mode: str = "warm"

    def __post_init__(self):
        if self.generations < 0:
            raise ValueError(f"fold generations must be >= 0, got {self.generations}")
        if self.mode not in FOLD_MODES:
            raise ValueError(f"folds must be one of {', '.join(FOLD_MODES)}, got {self.mode!r}")

    def settings(self, stage: identify.CMASettings) -> identify.CMASettings:
        """The CMA-ES settings of a fold of a fit made with `stage`."""
        if self.mode == "cold":
            return stage
        return dataclasses.replace(stage, max_generations=self.generations, restarts=0,
                                   sigma0=stage.sigma0 / 2)

    def start(self, best_units: np.ndarray, start_units: np.ndarray) -> np.ndarray:
        """Where a fold's search starts (unit coordinates along the whole box): the full fit's
        best point (warm) or the search's own start (cold)."""
        return start_units if self.mode == "cold" else best_units


@dataclasses.dataclass(frozen=True)
class Setup:
    """What every evaluation of the study shares."""
    gaits: Tuple[str, ...]
    trials: dict
    train: Tuple[int, int]
    validate: Tuple[int, int]
    run_kwargs: dict
    record_interval_s: float
    strokes: Optional[Dict[str, identification.Strokes]] = None
    """--phases strokes: each trial's measured strokes, read once, on which its phase is put
    where the simulated strokes meet them (`identification.stroke_aligned_phase`), in every
    window; None: each trial's phase fitted per window (the validation window holds the
    training one's)."""
    periods: Optional[Dict[str, float]] = None
    """--periods strokes: each gait's pulse period, s, read off its strokes' line (`Strokes`:
    period_s + drift_s): its model fires at that period and its track is cut into periods of
    it (the trials and strokes above were read with it); None: the model's own period."""


def simulate_points(params: Sequence[StarParams], last_cycle: int, setup: Setup) -> list:
    """`identification.SimulatedRun` of every model (None where it failed), simulated from rest
    for `last_cycle` cycles in one batch."""
    # the strokes of the window's last period are read over a window past its end
    tail = STROKE_TAIL_CYCLES if setup.strokes is not None else 0.0
    if setup.periods is not None:
        params = [p.replace(period=setup.periods[p.gait]) for p in params]
    result = run_batch(list(params), cycles=float(last_cycle) + tail,
                       record_interval_s=setup.record_interval_s, **setup.run_kwargs)
    return identification.result_runs(result, params)


def score(runs: Sequence, gaits: Sequence[str], setup: Setup, cycles,
          phases: Optional[Dict[str, float]] = None) -> Optional[pd.DataFrame]:
    """The trajectory objective's per-gait table of one point's runs (None if any failed);
    with `setup.strokes` at the stroke-aligned phases (`phases` then unused)."""
    if any(run is None for run in runs):
        return None
    if setup.strokes is not None:
        phases = {gait: identification.stroke_aligned_phase(run, setup.trials[gait], cycles,
                                                            setup.strokes[gait])
                  for gait, run in zip(gaits, runs)}
    return identification.trajectory_objective(dict(zip(gaits, runs)), setup.trials, cycles,
                                               phases=phases)


def evaluate(box, units, model: StarParams, gaits: Sequence[str], setup: Setup) -> pd.DataFrame:
    """One generation: every point (units (P, D)) on every gait in one batch, scored on the
    training cycles. One row per point: u_<axis>, the values, objective (inf if a simulation
    failed), n_direction_mismatches, then objective_<gait> and phase_<gait>_s."""
    units = np.atleast_2d(units)
    values = identify.box_values(box, units)
    params = identify.box_params(box, values, model, gaits)
    runs = simulate_points(params, setup.train[1], setup)
    table = pd.DataFrame({f"u_{s.key}": units[:, d] for d, s in enumerate(box)})
    for d, spec in enumerate(box):
        table[spec.column] = values[:, d]
    objective, mismatches = [], []
    per_gait = {f"objective_{g}": [] for g in gaits} | {f"phase_{g}_s": [] for g in gaits}
    for p in range(len(units)):
        scored = score(runs[p * len(gaits):(p + 1) * len(gaits)], gaits, setup, setup.train)
        objective.append(math.inf if scored is None else identification.objective_of(scored))
        mismatches.append(len(gaits) if scored is None
                          else int((~scored["direction_matches"]).sum()))
        for g, gait in enumerate(gaits):
            per_gait[f"objective_{gait}"].append(math.nan if scored is None
                                                 else scored["objective"].iloc[g])
            per_gait[f"phase_{gait}_s"].append(math.nan if scored is None
                                               else scored["phase_s"].iloc[g])
    table["objective"] = objective
    table["n_direction_mismatches"] = mismatches
    for column, values_ in per_gait.items():
        table[column] = values_
    return table


# --------------------------------------------------------------------------- one candidate

def fit_candidate(candidate: Candidate, base: StarParams, settings: identify.CMASettings,
                  fold_plan: FoldPlan, setup: Setup, on_generation=None,
                  progress: bool = False, start_model: Optional[StarParams] = None) -> dict:
    """Fit one candidate and assess it (module docstring), the search started at
    `start_model`'s values (--start; default the base model's). Returns {"row": the result row
    (without rank), "parameters", "gaits", "folds": tables, "best": the
    identified StarParams, "identified": its fields}."""
    start = time.perf_counter()
    model = candidate.model(base)
    box = candidate.box(base)
    gaits = list(setup.gaits)
    start_units = search_start(candidate, base, start_model)
    fit = identify.minimise_cmaes(box, start_units,
                                  lambda u: evaluate(box, u, model, gaits, setup), settings,
                                  progress=progress, on_generation=on_generation)
    evaluations = fit.evaluations
    row = {"candidate": candidate.name, "fit": candidate.fit, "set": candidate.set,
           "description": candidate.description, "n_fitted": len(box),
           "n_parameters": parameter_count(box, setup),
           "n_gaits": len(gaits),
           "n_evaluations": len(evaluations)}
    if identify.best_row(evaluations) is None:
        return {"row": {**row, "status": "fit_failed", "note": "every candidate point failed",
                        "fit_time_s": time.perf_counter() - start},
                "parameters": pd.DataFrame(), "gaits": pd.DataFrame(), "folds": pd.DataFrame(),
                "best": None, "identified": None}
    units = identify.best_units(evaluations, box)
    values = identify.box_values(box, units)[0]
    assessed = assess_point(candidate, base, units, values, settings, fold_plan, setup,
                            start_units)
    row.update(assessed.pop("row"), fit_time_s=time.perf_counter() - start)
    return {"row": row, "parameters": parameter_table(candidate.name, box, values, fit.unit_std),
            **assessed}


def reassess_candidate(candidate: Candidate, base: StarParams, settings: identify.CMASettings,
                       fold_plan: FoldPlan, setup: Setup, stored: dict, source: str,
                       start_model: Optional[StarParams] = None) -> dict:
    """--reassess: a finished fit (`stored`, its done/ record) assessed again at its best point
    (its parameter table's values, exact in JSON) as `fit_candidate` assesses a new one: the
    windows re-simulated and scored, the folds fitted anew as `fold_plan` says: warm, from the
    point's unit coordinates (`ParameterRange.unit` of its values: equal to the fit's to
    round-off); cold, from the search's start (`start_model`'s or the base model's values). The
    fit's own columns (n_evaluations, fit_time_s, the parameter table) are kept; the note names
    the fit's `source`."""
    parameters = pd.DataFrame(stored["parameters"])
    box = candidate.box(base)
    values = stored_values(box, parameters)
    units = np.array([spec.unit(value) for spec, value in zip(box, values)])
    assessed = assess_point(candidate, base, units, values, settings, fold_plan, setup,
                            search_start(candidate, base, start_model))
    row = {key: stored["row"][key] for key in ("candidate", "fit", "set", "description",
                                               "n_fitted", "n_parameters", "n_gaits",
                                               "n_evaluations", "fit_time_s")}
    row.update(assessed.pop("row"), note=f"assessed again (--reassess), the fit read back from "
                                         f"{source}")
    return {"row": row, "parameters": parameters, **assessed}


def search_start(candidate: Candidate, base: StarParams,
                 start_model: Optional[StarParams] = None) -> np.ndarray:
    """(D,) unit coordinates along the candidate's box where its search starts: --start's
    model (`start_model`) or the base model's values."""
    point = candidate.model(start_model if start_model is not None else base)
    return identify.start_units(candidate.box(base), point)


def assess_point(candidate: Candidate, base: StarParams, units: np.ndarray, values: np.ndarray,
                 settings: identify.CMASettings, fold_plan: FoldPlan, setup: Setup,
                 start_units: np.ndarray) -> dict:
    """The assessment of a candidate's best point (units and values (D,) along its box's axes;
    module docstring; `start_units` (D,) where its search started, for cold folds):
    {"row": status, errors, directions, information criteria; "gaits", "folds": tables;
    "best": the identified StarParams; "identified": its fields}."""
    model = candidate.model(base)
    box = candidate.box(base)
    gaits = list(setup.gaits)
    best = model.replace(**identify.point_changes(box, values, model))
    # training and validation windows from one simulation of the best point
    runs = simulate_points([best.replace(gait=g) for g in gaits], setup.validate[1], setup)
    train = score(runs, gaits, setup, setup.train)
    validate = (score(runs, gaits, setup, setup.validate, dict(zip(train["gait"],
                                                                    train["phase_s"])))
                if train is not None else None)  # strokes: each window its own phases
    folds = leave_one_gait_out(box, fold_plan.start(units, start_units), model, settings,
                               fold_plan, setup)
    n_samples = len(gaits) * (setup.train[1] - setup.train[0] + 1) * \
        identification.SAMPLES_PER_CYCLE
    k = parameter_count(box, setup)
    held = folds[folds["status"] == "ok"] if len(folds) else folds
    failed_folds = list(folds.loc[folds["status"] != "ok", "held_out_gait"]) if len(folds) else []
    row = {
        "status": "ok" if train is not None else "failed",
        # a held-out gait the fold could not predict counts: it scored only the others, and a
        # form whose prediction failed ranked above one that predicted badly (an audit, 2026-12)
        "note": (f"held-out prediction failed: {', '.join(failed_folds)}" if failed_folds
                 else ""),
        "train_objective": (identification.objective_of(train) if train is not None
                            else math.inf),
        "validate_objective": (identification.objective_of(validate) if validate is not None
                               else math.inf),
        "logo_objective": (math.inf if failed_folds else float(held["objective"].mean())
                           if len(held) else math.nan),
        "logo_directions_right": int(held["direction_matches"].sum()) if len(held) else 0,
        "logo_within_35pct": int((held["direction_matches"]
                                  & (held["speed_ratio"].sub(1).abs() <= 0.35)).sum())
        if len(held) else 0,
        "n_folds": len(folds),
        "train_directions_right": int(train["direction_matches"].sum()) if train is not None
        else 0,
        "validate_directions_right": int(validate["direction_matches"].sum())
        if validate is not None else 0,
        **information_criteria(train, k, n_samples)}
    windows = [table.assign(window=name) for name, table in
               (("train", train), ("validate", validate)) if table is not None]
    gait_rows = pd.concat(windows, ignore_index=True) if windows else pd.DataFrame()
    gait_rows.insert(0, "candidate", candidate.name)
    return {"row": row, "gaits": gait_rows, "folds": folds.assign(candidate=candidate.name),
            "best": best, "identified": identified_fields(best)}


def parameter_count(box, setup: Setup) -> int:
    """k of a fit: its axes, plus one phase per gait where the phases are fitted (held on the
    strokes, `setup.strokes`, they are not parameters)."""
    return len(box) + (len(setup.gaits) if setup.strokes is None else 0)


def information_criteria(train: Optional[pd.DataFrame], k: int, n_samples: int) -> dict:
    """chi2, n_samples, aic, bic of a fit from its training per-gait table: χ² = the samples
    per gait × Σ over the gaits of the gait's objective (its mean squared curve residual plus
    the direction residual², which thus weighs as much as a whole curve, as in the fit),
    AIC = χ² + 2k, BIC = χ² + k ln n_samples; inf without a table."""
    chi2 = (math.inf if train is None
            else float(train["objective"].sum()) * n_samples / len(train))
    return {"chi2": chi2, "n_samples": n_samples, "aic": chi2 + 2 * k,
            "bic": chi2 + k * math.log(n_samples)}


def identified_fields(best: StarParams) -> dict:
    """{field: value} of an identified model where it differs from StarParams' defaults (the
    gait aside; tuples as tuples): the dict of a preset (`taichi_star.params.PRESET_FIELDS`)."""
    default = StarParams()
    return {name: getattr(best, name) for name in StarParams.field_names()
            if name != "gait" and getattr(best, name) != getattr(default, name)}


def best_model(candidate: Candidate, base: StarParams, parameters: pd.DataFrame) -> StarParams:
    """A candidate's identified model from its rows of the parameter table (a finished
    candidate read back)."""
    model = candidate.model(base)
    box = candidate.box(base)
    return model.replace(**identify.point_changes(box, stored_values(box, parameters), model))


def stored_values(box, parameters: pd.DataFrame) -> np.ndarray:
    """The identified values (D,) along the box's axes from a candidate's rows of the parameter
    table."""
    return parameters.set_index("parameter").loc[[spec.label for spec in box],
                                                  "value"].to_numpy(dtype=float)


def identified_table(row: dict, fields: dict,
                     periods: Optional[Dict[str, float]] = None) -> pd.DataFrame:
    """identified.csv: one row per field of the best candidate's model (field, value as Python
    text, the candidate and its errors); with --periods strokes (`periods`, s per gait) a
    column fitted_at_periods saying at which periods the fields were fitted (the model's own
    `period` is not among them)."""
    table = pd.DataFrame([{"field": name, "value": repr(value), "candidate": row["candidate"],
                           "stage": row["stage"], "train_objective": row["train_objective"],
                           "validate_objective": row["validate_objective"],
                           "logo_objective": row["logo_objective"]}
                          for name, value in fields.items()])
    if periods:
        table["fitted_at_periods"] = periods_text(periods)
    return table


def periods_text(periods: Dict[str, float]) -> str:
    """"each gait at its strokes' period: A1 3.182 s, ..." (s per gait)."""
    return "each gait at its strokes' period: " + ", ".join(
        f"{gait} {period:.3f} s" for gait, period in periods.items())


def parameter_table(name: str, box, values, unit_std) -> pd.DataFrame:
    """The identified values with their spread: σ_u (unit coordinates) mapped through the
    axis' scale, (high − low)·σ_u or value·ln(high/low)·σ_u for a log axis."""
    rows = []
    for spec, value, spread in zip(box, values, unit_std):
        scale = spec.value_per_unit(value)
        rows.append({"candidate": name, "parameter": spec.label, "column": spec.column,
                     "value": float(value), "std": float(scale * spread), "unit_std": float(spread),
                     "low": spec.low, "high": spec.high, "log": spec.log})
    return pd.DataFrame(rows)


def leave_one_gait_out(box, units, model: StarParams, settings: identify.CMASettings,
                       fold_plan: FoldPlan, setup: Setup) -> pd.DataFrame:
    """The folds (`fold_plan`: how they are fitted) of a fit made with `settings`, each
    started at `units` (D,) along the box (`FoldPlan.start`). One row per held-out gait:
    held_out_gait, n_fold_axes (axes its fold fitted), frozen_axes (left at their prior),
    fold_move_units (how far the fold's best point lies from its start, the largest move along
    an axis in unit coordinates: a warm fold starts where the fit that saw the held-out gait
    ended, and one that hardly moves predicts with that fit's point), objective (the held-out
    gait on the training cycles), sim_speed_mm_s (signed), meas_speed_mm_s, speed_ratio
    (|sim| / meas), direction_matches, status ("ok"; "failed" where the prediction's run
    failed; "fit_failed" where every point of the fold's fit failed). Every fold's prediction
    is simulated in one batch."""
    gaits = list(setup.gaits)
    if fold_plan.generations == 0 or len(gaits) < 2:
        return pd.DataFrame()
    predictions, notes = [], []
    fold_settings = fold_plan.settings(settings)
    for held_out in gaits:
        fitted = [g for g in gaits if g != held_out]
        informed = informed_axes(box, model, fitted)
        fold_box = [spec for spec, keep in zip(box, informed) if keep]
        frozen = [spec.label for spec, keep in zip(box, informed) if not keep]
        point, move, fit_failed = {}, 0.0, False
        if fold_box:
            fold_setup = dataclasses.replace(setup, gaits=tuple(fitted))
            start = np.array([u for u, keep in zip(units, informed) if keep])
            fold = identify.minimise_cmaes(
                fold_box, start, lambda u: evaluate(fold_box, u, model, fitted, fold_setup),
                fold_settings)
            fit_failed = identify.best_row(fold.evaluations) is None
            if not fit_failed:
                fold_units = identify.best_units(fold.evaluations, fold_box)
                fold_values = identify.box_values(fold_box, fold_units)[0]
                point = identify.point_changes(fold_box, fold_values, model)
                move = float(np.max(np.abs(fold_units - start)))
        predictions.append(model.replace(gait=held_out, **point))
        notes.append((held_out, len(fold_box), " ".join(frozen), move, fit_failed))
    runs = simulate_points(predictions, setup.train[1], setup)
    rows = []
    for (held_out, n_axes, frozen, move, fit_failed), run in zip(notes, runs):
        scored = None if fit_failed else score([run], [held_out], setup, setup.train)
        if scored is None:
            # a fold whose every point failed predicts nothing (it predicted from the prior
            # before, silently: an audit, 2026-12)
            rows.append({"held_out_gait": held_out, "n_fold_axes": n_axes, "frozen_axes": frozen,
                         "fold_move_units": move,
                         "status": "fit_failed" if fit_failed else "failed",
                         "objective": math.inf})
            continue
        line = scored.iloc[0]
        rows.append({"held_out_gait": held_out, "n_fold_axes": n_axes, "frozen_axes": frozen,
                     "fold_move_units": move,
                     "objective": float(line["objective"]),
                     "sim_speed_mm_s": float(line["sim_speed_mm_s"]),
                     "meas_speed_mm_s": float(line["meas_speed_mm_s"]),
                     "speed_ratio": abs(line["sim_speed_mm_s"]) / line["meas_speed_mm_s"],
                     "direction_matches": bool(line["direction_matches"]), "status": "ok"})
    return pd.DataFrame(rows)


# --------------------------------------------------------------------------- the study

def ranked(rows: Sequence[dict]) -> pd.DataFrame:
    """The result rows ranked: the refined forms, then the screened ones (`STAGES`; a row
    without a stage is a screened one); within a stage, fitted candidates by held-out error
    (`held_out_objective`: held-out gaits plus later cycles, each a test of prediction; then
    BIC, then training error), skipped or failed ones after them; rank 1 is the best."""
    table = pd.DataFrame(list(rows))
    for column in RESULT_COLUMNS:
        if column not in table:
            table[column] = math.nan
    table["stage"] = table["stage"].where(table["stage"].isin(STAGES), "screen")
    table["_stage"] = table["stage"].map(STAGES.index)
    table["_ok"] = table["status"] == "ok"
    # no folds (--fold-generations 0, a single gait: logo_objective NaN): the later cycles
    # alone (the sum was NaN for every row, and the rank fell through to BIC: an audit, 2026-12)
    held_out = (table["logo_objective"].astype(float).fillna(0.0)
                + table["validate_objective"].astype(float))
    table["held_out_objective"] = held_out
    table["_held_out"] = held_out.where(np.isfinite(held_out), math.inf)
    table = table.sort_values(["_stage", "_ok", "_held_out", "bic", "train_objective"],
                              ascending=[True, False, True, True, True], kind="stable")
    table["rank"] = np.arange(1, len(table) + 1)
    return table[RESULT_COLUMNS].reset_index(drop=True)


def refined_candidates(screen: pd.DataFrame, runnable: Sequence[Candidate],
                       top: int) -> List[Candidate]:
    """The `top` best fitted candidates of the ranked screen, in rank order."""
    by_name = {candidate.name: candidate for candidate in runnable}
    fitted = screen[(screen["status"] == "ok") & screen["candidate"].isin(by_name)]
    return [by_name[name] for name in fitted["candidate"].head(top)]


def definition_of(candidate: Candidate, args, settings, base: StarParams,
                  solver: SolverConfig, gaits,
                  start_model: Optional[StarParams] = None) -> str:
    """SHA-256 of what defines a candidate's result (a resumed run reuses it only if equal). The
    base model (and --start's, where given) enters by its fields that differ from StarParams'
    defaults, so a field added to StarParams later (a new model option, off by default) leaves
    earlier results reusable."""
    def changes(model: StarParams) -> dict:
        return {name: repr(value) for name, value in changed_fields(model).items()}
    base_changes = changes(base)
    start = {} if start_model is None else {"start": changes(start_model)}
    # --phases enters only where it is not the default, which earlier results were made with
    phases = ({} if args.phases == "fitted" else
              {"phases": args.phases, "stroke_alignment": STROKE_ALIGNMENT})
    periods = {} if args.periods == "nominal" else {"periods": args.periods}
    # and --folds (cold folds, added later; every earlier result had warm ones)
    fold_mode = {} if args.folds == "warm" else {"folds": args.folds}
    text = json.dumps({"candidate": dataclasses.asdict(candidate),
                       "settings": dataclasses.asdict(settings),
                       "fold_generations": args.fold_generations, "gaits": list(gaits),
                       "train": args.train_cycles, "validate": args.validate_cycles,
                       "base": base_changes, "solver": repr(solver), **phases, **periods,
                       **fold_mode, **start},
                      sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def stored_fit_of(done: Path, folder: Path, evaluations: str, candidate: Candidate, args,
                  settings, base: StarParams, solver: SolverConfig, gaits,
                  start_model: Optional[StarParams] = None) -> Optional[Tuple[dict, str]]:
    """--reassess: a candidate's finished fit, its record `done` (in `folder`/done/), with the
    text naming it (`evaluations`, the CSV of its evaluations in `folder`, and the commit that
    fitted them, from its sidecar where `read_provenance` reads it) if it was fitted as today's
    run would fit it (its definition today's: `definition_of`, whichever --folds it was
    assessed with, the folds being done again), else None (it is fitted anew)."""
    stored = read_done(done)
    if stored is None or stored["row"].get("status") != "ok":
        return None
    definitions = {definition_of(candidate, argparse.Namespace(**{**vars(args), "folds": mode}),
                                 settings, base, solver, gaits, start_model=start_model)
                   for mode in FOLD_MODES}
    if stored["row"].get("definition") not in definitions:
        return None
    return stored, fit_named(folder, evaluations)


def fit_named(folder: Path, evaluations: str) -> str:
    """The text naming a stored fit: `evaluations` (the CSV of its evaluations in `folder`)
    and the commit that fitted them, from its sidecar where `read_provenance` reads it."""
    commit = ""
    if (folder / f"{evaluations}.json").exists():
        try:
            commit = (read_provenance(folder / evaluations).get("git_commit") or "")[:7]
        except (OSError, ValueError) as error:
            # the commit only names the fit (done/ holds it): a sidecar damaged, or the
            # evaluations edited since, leave it out, which is said
            print(f"{str(error).splitlines()[0]}; the fit is named without its commit")
    return evaluations + (f", fitted at {commit}" if commit else "")


RECORD_TABLES = ("parameters", "gaits", "folds")
"""The tables of a fit's record in done/, each {column: list of values}."""


def done_record_bytes(record: dict) -> bytes:
    """A fit's record as done/ keeps it: the record's JSON text with its SHA-256, so that a
    damaged one is known (a value changed by hand or by the disk was read back as the fit's
    result without a word: an audit, 2026-12)."""
    text = json.dumps(record, default=_json_value)
    return json.dumps({"sha256": hashlib.sha256(text.encode()).hexdigest(),
                       "record": text}).encode()


def read_done(done: Path) -> Optional[dict]:
    """A finished fit's record in done/ (`done_record_bytes`), None where there is none or it
    cannot be trusted (its checksum does not match, a table or a row's figure is missing, or
    it cannot be read): that candidate is fitted again, which is said. A record from before
    the checksums (the committed ones) is read on its shape alone."""
    if not done.exists():
        return None
    try:
        stored = json.loads(done.read_text())
        if isinstance(stored, dict) and set(stored) == {"sha256", "record"}:
            text = stored["record"]
            if not isinstance(text, str) or \
                    hashlib.sha256(text.encode()).hexdigest() != stored["sha256"]:
                raise ValueError("its record does not match its checksum")
            stored = json.loads(text)
        check_done_record(stored)
    except (OSError, ValueError) as error:
        print(f"{done}: unreadable ({str(error).splitlines()[0]}); its candidate is fitted again")
        return None
    return stored


def check_done_record(stored) -> None:
    """ValueError unless `stored` has a fit record's shape: a row (a dict with a status, and
    for a fit that ended ok its parameter and sample counts) and its tables, each columns of
    equal length (a record lacking one failed with a KeyError after the fits before it: an
    audit, 2026-12)."""
    if not isinstance(stored, dict) or not isinstance(stored.get("row"), dict) \
            or "status" not in stored["row"]:
        raise ValueError("not a fit's record")
    if stored["row"]["status"] == "ok" and not all(
            isinstance(stored["row"].get(key), (int, float)) for key in ("n_parameters",
                                                                       "n_samples")):
        raise ValueError("its row lacks the counts of parameters and samples")
    for name in RECORD_TABLES:
        table = stored.get(name)
        if not isinstance(table, dict) or not all(isinstance(column, list)
                                                  for column in table.values()) \
                or len({len(column) for column in table.values()}) > 1:
            raise ValueError(f"its {name} table is missing or not columns of equal length")


def estimate_seconds(seconds_per_instance_cycle: float,
                     work: Sequence[Tuple[Candidate, identify.CMASettings]],
                     fold_plan: FoldPlan, n_gaits: int, train_last: int,
                     validate_last: int) -> float:
    """Predicted run time (s) of the fits in `work` ((candidate, settings) pairs) from the
    measured cost of one simulated instance-cycle: every generation of every restart, the
    folds (`fold_plan`: how they are fitted), the assessment runs and the Fig. 4c runs, at each
    candidate's population."""
    cycles = 0.0
    for candidate, settings in work:
        cycles += fit_instances(candidate, settings, fold_plan, n_gaits) * train_last
        cycles += n_gaits * validate_last + 5 * train_last
    return cycles * seconds_per_instance_cycle


def fit_instances(candidate: Candidate, settings: identify.CMASettings, fold_plan: FoldPlan,
                  n_gaits: int) -> int:
    """The instances one fit of `candidate` at `settings` simulates at most, each over the
    training window: every generation of every restart on every gait, and with folds
    (`leave_one_gait_out`, fitted as `fold_plan` says) each held-out gait's fit on the others
    and its prediction; the assessment's runs of the best point aside."""
    dimension = len(candidate.fit.split())
    instances = settings.evaluations(dimension) * n_gaits
    if fold_plan.generations and n_gaits > 1:
        instances += n_gaits * (fold_plan.settings(settings).evaluations(dimension)
                                * (n_gaits - 1) + 1)
    return instances


def planned_work(runnable: Sequence[Candidate], settings: identify.CMASettings,
                 refine_settings: identify.CMASettings,
                 refine_top: int) -> List[Tuple[Candidate, identify.CMASettings]]:
    """Every fit the study will run, for its estimate: each candidate at the screen's budget,
    then, standing in for the refined forms (unknown until the screen is ranked), the
    `refine_top` candidates of most axes at the refine budget (an upper bound)."""
    largest = sorted(runnable, key=lambda c: len(c.fit.split()), reverse=True)[:refine_top]
    return ([(candidate, settings) for candidate in runnable]
            + [(candidate, refine_settings) for candidate in largest])


def planned_instances(work: Sequence[Tuple[Candidate, identify.CMASettings]],
                      fold_plan: FoldPlan, n_gaits: int) -> int:
    """The instances the fits in `work` (`planned_work`) simulate at most, for the cap on a
    study's work (`cli.check_instances`): `fit_instances` summed over them."""
    return sum(fit_instances(candidate, settings, fold_plan, n_gaits)
               for candidate, settings in work)


def measured_strokes(trials, last_cycle: int, flag: str = "--phases strokes"
                     ) -> Dict[str, identification.Strokes]:
    """--phases strokes, before any compute: each trial's `identification.strokes`;
    StudyArgumentError (naming `flag`, the option that asked for them) naming a gait whose
    strokes lie on no period (`Strokes.periodic`) or end before the windows'
    last cycle (and one period more)."""
    read = {}
    for gait, trial in trials.items():
        measured = identification.strokes(trial.path)
        if not measured.periodic:
            raise cli.StudyArgumentError(
                f"{flag}: {gait}'s strokes do not lie on one period "
                f"({measured.on_line_cycles} of {measured.cycles} within "
                f"{identification.STROKE_TOLERANCE_S:g} s of their line), so there is no "
                f"phase to hold; leave it out with --gaits")
        if measured.cycles < last_cycle + 1:
            raise cli.StudyArgumentError(
                f"{flag}: {gait}'s track has {measured.cycles} strokes, the windows end at "
                f"cycle {last_cycle} (one period more is needed)")
        read[gait] = measured
    return read


def build_parser():
    parser = cli.StudyParser("model_select", DESCRIPTION)
    parser.add_argument("--candidates", default=None, metavar="CSV",
                        help=f"the candidate table (CSV: name, set, fit, description; default "
                             f"{CANDIDATES_CSV.name}; --quick: two toy candidates)")
    parser.add_argument("--only", default=None,
                        help="comma list of candidate names to run (default: all)")
    parser.add_argument("--gaits", default="paper", quick=QUICK_GAITS,
                        help="measured gaits to fit: paper (all five) or a comma list")
    parser.add_argument("--phases", choices=PHASE_MODES, default="fitted",
                        help="each trial's pulse phase: fitted per window (the validation "
                             "window holds the training one's), or strokes: where the "
                             "simulated strokes meet the measured ones, in every window")
    parser.add_argument("--periods", choices=PERIOD_MODES, default="nominal",
                        help="each trial's pulse period: nominal (the model's, 3.15 s), or "
                             "strokes: the period its strokes' line gives (with --phases "
                             "strokes), at which its model fires and its track is cut")
    parser.add_argument("--train-cycles", default="1:3", quick="1:1",
                        help="the fit window FIRST:LAST (cycles from 1)")
    parser.add_argument("--validate-cycles", default="4:6", quick="2:2",
                        help="the validation window FIRST:LAST")
    parser.add_argument("--popsize", type=int, default=DEFAULT_POPSIZE, quick=QUICK_POPSIZE,
                        help="CMA-ES population, >= 2, doubled at each restart")
    parser.add_argument("--max-generations", type=int, default=DEFAULT_MAX_GENERATIONS,
                        quick=QUICK_MAX_GENERATIONS, help="generations per CMA-ES run, >= 1")
    parser.add_argument("--fold-generations", type=int, default=DEFAULT_FOLD_GENERATIONS,
                        quick=QUICK_FOLD_GENERATIONS,
                        help="generations of each leave-one-gait-out fit with --folds warm "
                             "(0: no folds, with either --folds)")
    parser.add_argument("--folds", choices=FOLD_MODES, default="warm",
                        help="warm: each fold starts at the full fit's best point with half its "
                             "step (cheap; its start saw the held-out gait); cold: each fold is "
                             "a fit of its own from the search's start at the stage's budget "
                             "(default warm)")
    parser.add_argument("--refine-top", type=int, default=DEFAULT_REFINE_TOP,
                        quick=QUICK_REFINE_TOP,
                        help="refit the K best screened forms at the refine budget (0: no "
                             "refine stage)")
    parser.add_argument("--refine-popsize", type=int, default=DEFAULT_REFINE_POPSIZE,
                        quick=QUICK_REFINE_POPSIZE,
                        help="CMA-ES population of the refine stage")
    parser.add_argument("--refine-generations", type=int, default=DEFAULT_REFINE_GENERATIONS,
                        quick=QUICK_REFINE_GENERATIONS,
                        help="generations per CMA-ES run of the refine stage")
    parser.add_argument("--restarts", type=int, default=1, quick=0,
                        help=f"extra CMA-ES runs from random points (multi-start, IPOP; at most "
                             f"{identify.MAX_RESTARTS})")
    parser.add_argument("--start", default=None, metavar="CSV",
                        help="start every search at the model of an earlier run's "
                             "identified.csv (its fields on --preset's model; the prior that "
                             "a held-out fold keeps stays --preset's)")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    parser.add_argument("--sigma0", type=float, default=0.25,
                        help="initial CMA-ES step in unit coordinates, in (0, 1] (default 0.25)")
    parser.add_argument("--budget-hours", type=float, default=2.0,
                        help="wall-clock budget: candidates that would start after it are "
                             "skipped; the first fit always runs (default 2)")
    parser.add_argument("--resume", action="store_true",
                        help="reuse the finished candidates in --out (same definition)")
    parser.add_argument("--reassess", action="store_true",
                        help="assess the finished fits in --out again (same fit definition): "
                             "their best points re-simulated and scored, folds refitted; "
                             "candidates without one are fitted")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser, quick=QUICK_DT)
    cli.add_execution_flags(parser)
    return parser


def select_candidates(args) -> List[Candidate]:
    if args.candidates is not None and not args.candidates.strip():
        raise cli.StudyArgumentError("--candidates: an empty file name (give a table, e.g. "
                                     f"{CANDIDATES_CSV.name})")
    if args.candidates is None and args.quick:
        candidates = [Candidate(**c) for c in QUICK_CANDIDATES]
    else:
        candidates = read_candidates(args.candidates or CANDIDATES_CSV)
    if args.only is not None:
        names = cli.parse_choices(args.only, "--only", [c.name for c in candidates])
        candidates = [c for c in candidates if c.name in names]
    return candidates


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    settings = identify.CMASettings(popsize=args.popsize, max_generations=args.max_generations,
                                    restarts=args.restarts, seed=args.seed, sigma0=args.sigma0)
    settings.validate()
    for flag, value, least in (("--refine-top", args.refine_top, 0),
                               ("--refine-popsize", args.refine_popsize, 2),
                               ("--refine-generations", args.refine_generations, 1)):
        if value < least:
            raise cli.StudyArgumentError(f"{flag} must be >= {least}, got {value}")
    refine_settings = dataclasses.replace(settings, popsize=args.refine_popsize,
                                          max_generations=args.refine_generations)
    if args.fold_generations < 0:
        raise cli.StudyArgumentError(f"--fold-generations must be >= 0, got "
                                     f"{args.fold_generations}")
    fold_plan = FoldPlan(args.fold_generations, args.folds)
    cli.check_positive(args.budget_hours, "--budget-hours")
    if args.reassess:
        if args.resume:
            raise cli.StudyArgumentError("--resume and --reassess: give one (read the finished "
                                         "candidates back, or assess their fits again)")
        if args.out is None or not (Path(args.out) / "done").is_dir():
            raise cli.StudyArgumentError(
                "--reassess: give --out, a folder of an earlier run (with done/)"
                if args.out is None else
                f"--reassess: --out {args.out} has no done/ folder (give the folder of an "
                f"earlier run)")
    if args.periods == "strokes" and args.phases != "strokes":
        raise cli.StudyArgumentError("--periods strokes needs --phases strokes (the periods "
                                     "are read off the strokes' lines)")
    train, validate = identify.parse_windows(args.train_cycles, args.validate_cycles)
    gaits = identify.measured_gaits(args.gaits)
    base = cli.base_params(args)
    start_model = identify.read_start(args.start, base) if args.start is not None else None
    candidates = select_candidates(args)
    if args.periods == "strokes":
        # the measured periods replace every model's own: a period asked for would be dropped
        asked = ["--set" for item in args.set
                 if cli.parse_assignment(item, "--set")[0] == "period"]
        asked += [f"candidate {c.name}" for c in candidates if "period" in c.field_names()]
        if asked:
            raise cli.StudyArgumentError(
                f"{asked[0]}: sets or fits period, which --periods strokes reads off each "
                f"trial's strokes instead; leave out one or the other")
    runnable, rows = [], []
    for candidate in candidates:  # every runnable candidate checked before any compute
        missing = candidate.missing_fields()
        if missing:
            rows.append(candidate.skipped(f"StarParams has no field {', '.join(missing)}"))
            continue
        box = candidate.box(base)
        idle = identify.unfired_axes(box, gaits)
        if len(idle) == len(box):
            # a flat objective: its fit was ranked and "identified" from CMA-ES's random points
            # (a review, 2026-12)
            rows.append(candidate.skipped(f"no fitted gait fires the actuators of "
                                          f"{', '.join(idle)}"))
            continue
        identify.check_unfired_axes("model_select", f"candidate {candidate.name}", box, gaits)
        runnable.append(candidate)
    if not candidates:  # a header alone: rows[0] below was an IndexError (an audit, 2026-12)
        raise cli.StudyArgumentError("--candidates: no candidates (the table has no rows)")
    if not runnable:  # tables of skipped rows, exit status 0, before
        raise cli.StudyArgumentError(f"--candidates: none can be fitted ({rows[0]['candidate']}:"
                                     f" {rows[0]['note']})")
    cli.check_instances(
        planned_instances(planned_work(runnable, settings, refine_settings, args.refine_top),
                          fold_plan, len(gaits)),
        f"{len(runnable)} candidate(s) × {len(gaits)} gait(s) × --max-generations "
        f"{settings.max_generations} × --popsize {settings.popsize} (doubled at each of "
        f"--restarts {settings.restarts}), with "
        + (f"--fold-generations {args.fold_generations}" if args.folds == "warm"
           else "--folds cold (a whole fit)")
        + f" per held-out gait and the --refine-top {args.refine_top} refitted at "
        f"--refine-generations {refine_settings.max_generations} × --refine-popsize "
        f"{refine_settings.popsize}")
    trials = identification.measured_trials(gaits)
    identify.check_trials_cover(trials, validate, args.validate_cycles)
    last_cycle = max(train[1], validate[1])
    strokes = measured_strokes(trials, last_cycle) if args.phases == "strokes" else None
    periods = None
    if args.periods == "strokes":
        periods = {gait: read.period_s + read.drift_s for gait, read in strokes.items()}
        trials = {gait: identification.measured_trial(gait, period)
                  for gait, period in periods.items()}
        identify.check_trials_cover(trials, validate, args.validate_cycles)
        # their lines read anew (~flat), the tracks being cut into the longer periods
        strokes = measured_strokes(trials, last_cycle, "--periods strokes")
    solver = cli.solver(args)
    # every fit runs each model from rest over the windows' last cycle (and the strokes'
    # tail): at the longest period a model can have (its own, a fitted one's upper bound, or
    # the strokes') it must stay within the step counter (--dt 1e-9 was a traceback)
    cycles = last_cycle + (STROKE_TAIL_CYCLES if strokes is not None else 0.0)
    longest = max(periods.values()) if periods is not None else max(
        period for candidate in runnable
        for period in (candidate.model(base).period, *cli.range_periods(candidate.box(base))))
    cli.check_run(f"--train-cycles, --validate-cycles ({cycles:g} cycles of the longest period, "
                  f"{longest:g} s: {cycles * longest:.3g} s)", cycles * longest, solver)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"gaits": gaits, "train_cycles": list(train),
                                           "validate_cycles": list(validate),
                                           "cma": dataclasses.asdict(settings),
                                           "refine_top": args.refine_top,
                                           "refine_cma": dataclasses.asdict(refine_settings),
                                           "fold_generations": args.fold_generations,
                                           "folds": args.folds,
                                           "phases": args.phases, "periods": args.periods,
                                           "stroke_alignment": STROKE_ALIGNMENT,
                                           "budget_hours": args.budget_hours,
                                           "resume": bool(args.resume),
                                           "reassess": bool(args.reassess),
                                           **({"start": {"file": str(args.start),
                                                         "fields": identified_fields(
                                                             start_model)}}
                                              if start_model is not None else {}),
                                           **({"pulse_periods_s": periods} if periods
                                              else {})})
    out.resume_records = out.folder / "done"
    progress = not args.no_progress
    record = nearest_interval(identify.RECORD_INTERVAL_S, solver.dt)
    started = time.perf_counter()
    rows, parameters, gait_tables, fold_tables, identified = list(rows), [], [], [], {}
    budget_s = 3600 * args.budget_hours
    first_fit_done = False

    def fit_or_read_back(candidate: Candidate, stage_settings, stage: str, setup: Setup,
                         work_left):
        """One candidate at one stage: read back from done/ (--resume, same definition) or
        fitted, assessed and stored; skipped with a note once the budget is spent."""
        nonlocal first_fit_done
        definition = definition_of(candidate, args, stage_settings, base, solver, gaits,
                                   start_model=start_model)
        subfolder = "" if stage == "screen" else f"{stage}/"
        done = out.folder / "done" / subfolder / f"{candidate.name}.json"
        tables = (parameters, gait_tables, fold_tables)
        stored_fit = (stored_fit_of(done, out.folder, f"fits/{subfolder}{candidate.name}.csv",
                                    candidate, args, stage_settings, base, solver, gaits,
                                    start_model)
                      if args.reassess else None)
        stored = read_done(done) if args.resume else None
        if stored is not None:
            if stored["row"].get("definition") == definition:
                stored_gaits = pd.DataFrame(stored["gaits"])
                if stored["row"]["status"] == "ok":
                    stored["row"].update(information_criteria(
                        stored_gaits[stored_gaits["window"] == "train"],
                        stored["row"]["n_parameters"], stored["row"]["n_samples"]))
                # the row says where it came from: the run's sidecar names only the commit
                # that read it back (an audit, 2026-12)
                origin = "read back: " + fit_named(out.folder,
                                                   f"fits/{subfolder}{candidate.name}.csv")
                earlier = stored["row"].get("note")
                note = "; ".join(part for part in (earlier if isinstance(earlier, str) else "",
                                                   origin) if part)
                rows.append({**stored["row"], "note": note, "stage": stage})
                stored_parameters = pd.DataFrame(stored["parameters"])
                for store, table in zip(tables, (stored_parameters, stored_gaits,
                                                 pd.DataFrame(stored["folds"]))):
                    store.append(table.assign(stage=stage) if len(table) else table)
                identified[(stage, candidate.name)] = (
                    identified_fields(best_model(candidate, base, stored_parameters))
                    if stored["row"]["status"] == "ok" else None)
                print(f"{candidate.name} ({stage}): read back from {done}")
                return
        # the first fit of a run always runs: a budget spent before it (--budget-hours 1e-9)
        # skipped every candidate and wrote empty tables with exit status 0 (an audit, 2026-12)
        if first_fit_done and time.perf_counter() - started > budget_s:
            rows.append({"stage": stage, **candidate.skipped(f"budget of "
                                                             f"{args.budget_hours:g} h spent"),
                         "definition": definition})
            return
        timing = {"last": time.perf_counter(), "generations": 0}
        label = candidate.name if stage == "screen" else f"{candidate.name} ({stage})"

        def on_generation(table):
            out.write_csv(table, f"fits/{subfolder}{candidate.name}.csv")
            now = time.perf_counter()
            seconds, timing["last"] = now - timing["last"], now
            timing["generations"] += 1
            if timing["generations"] <= 2:  # the first compiles; the second is steady
                points = len(table) // timing["generations"]
                per = seconds / (points * len(gaits) * train[1])
                estimate = estimate_seconds(per, work_left, fold_plan, len(gaits),
                                            train[1], validate[1])
                print(f"{label}: generation {timing['generations']} took {seconds:.1f} s "
                      f"({points} points x {len(gaits)} gaits x {train[1]} cycles"
                      f"{', compile included' if timing['generations'] == 1 else ''}); "
                      f"estimate for the {len(work_left)} fit(s) left: "
                      f"{estimate / 60:.1f} min (budget left "
                      f"{(budget_s - (now - started)) / 60:.1f} min)")

        if stored_fit is not None:
            print(f"{label}: assessed again, the fit read back from {stored_fit[1]}")
            result = reassess_candidate(candidate, base, stage_settings, fold_plan, setup,
                                        *stored_fit, start_model=start_model)
        else:
            result = fit_candidate(candidate, base, stage_settings, fold_plan,
                                   setup, on_generation=on_generation, progress=progress,
                                   start_model=start_model)
        first_fit_done = True
        result["row"].update(definition=definition, stage=stage)
        rows.append(result["row"])
        for store, table in zip(tables, (result["parameters"], result["gaits"],
                                         result["folds"])):
            store.append(table.assign(stage=stage) if len(table) else table)
        identified[(stage, candidate.name)] = result["identified"]
        if result["best"] is not None:
            suffix = "" if stage == "screen" else "_refined"
            figures.run_fig4c(out, result["best"], solver,
                              duration_s=cli.duration_s(args, result["best"].period)
                              if args.quick else train[1] * result["best"].period,
                              arch=args.arch, prefix=f"fig4c_{candidate.name}{suffix}",
                              progress=False, title_note=f"model {label}")
        done.parent.mkdir(parents=True, exist_ok=True)
        # whole or not at all: a kill mid-write left a record --resume could not read (an
        # audit, 2026-12)
        write_atomic(done, done_record_bytes({
            "row": result["row"],
            "parameters": result["parameters"].to_dict(orient="list"),
            "gaits": result["gaits"].to_dict(orient="list"),
            "folds": result["folds"].to_dict(orient="list")}),
            failure=lambda reason: cli.StudyOutputError(
                f"{reason}; the fits recorded before are kept: --resume continues"))

    with cli.executor(args, out) as executor:
        work = planned_work(runnable, settings, refine_settings, args.refine_top)
        largest = max((fit_settings.population(len(c.fit.split()), fit_settings.restarts)
                       for c, fit_settings in work), default=1) * len(gaits)
        setup = Setup(tuple(gaits), trials, train, validate,
                      # no bar per evaluation: the fit's own bar counts its generations (and
                      # --no-progress means none at all)
                      dict(solver=solver, arch=args.arch, executor=executor, progress=False,
                           chunk_size=cli.chunk_size(args, largest, executor.n_workers)),
                      record, strokes, periods)
        for position, candidate in enumerate(runnable):
            fit_or_read_back(candidate, settings, "screen", setup, work[position:])
        refined = refined_candidates(ranked(rows), runnable, args.refine_top)
        for position, candidate in enumerate(refined):
            fit_or_read_back(candidate, refine_settings, "refine", setup,
                             [(c, refine_settings) for c in refined[position:]])
    table = ranked(rows)
    csv = out.write_csv(table, "model_select.csv")
    non_empty = [t for t in parameters if len(t)]
    out.write_csv(pd.concat(non_empty, ignore_index=True) if non_empty else pd.DataFrame(),
                  "model_select_parameters.csv")
    non_empty = [t for t in gait_tables if len(t)]
    out.write_csv(pd.concat(non_empty, ignore_index=True) if non_empty else pd.DataFrame(),
                  "model_select_gaits.csv")
    non_empty = [t for t in fold_tables if len(t)]
    out.write_csv(pd.concat(non_empty, ignore_index=True) if non_empty else pd.DataFrame(),
                  "model_select_folds.csv")
    out.wrote(plot_ranking(csv, out.path("model_select.png")))
    best = table.iloc[0]
    fields = identified.get((best["stage"], best["candidate"]))
    if best["status"] == "ok" and fields is not None:
        out.write_csv(identified_table(best.to_dict(), fields, periods), "identified.csv")
        print(f"identified preset (rank 1, {best['candidate']}, {best['stage']}): "
              f"IDENTIFIED_FIELDS = {fields!r}"
              + (f" (fitted with {periods_text(periods)})" if periods else ""))
    out.report()
    print(table[["rank", "stage", "candidate", "status", "train_objective", "validate_objective",
                 "logo_objective", "logo_directions_right", "train_directions_right", "bic",
                 "note"]].to_string(index=False))
    print(f"model_select: {(time.perf_counter() - started) / 60:.1f} min")
    return table


def _json_value(value):
    """JSON for the values of a finished candidate's record: NumPy scalars as numbers, other
    objects as their text."""
    return value.item() if isinstance(value, np.generic) else repr(value)


def fitted_candidates(csv_path) -> pd.DataFrame:
    """The rows of model_select.csv whose fit is "ok", in rank order, the candidates' names as
    written (`cli.NAMES_AS_WRITTEN`: "NA" or "null" became NaN, two bars of the ranking
    labelled "nan", an audit)."""
    table = pd.read_csv(csv_path, **cli.NAMES_AS_WRITTEN)
    return table[table["status"] == "ok"]


def plot_ranking(csv_path, png_path) -> Path:
    """Bars from model_select.csv: each fitted candidate's training, validation and held-out
    objective (log scale), in rank order (the refined forms first, labelled so)."""
    plt = cli.use_agg()
    table = fitted_candidates(csv_path)
    fig, ax = plt.subplots(figsize=(max(5.0, 1.1 * len(table) + 2), 4.5))
    width = 0.27
    x = np.arange(len(table))
    for offset, column, label in ((-width, "train_objective", "training cycles"),
                                  (0.0, "validate_objective", "validation cycles"),
                                  (width, "logo_objective", "held-out gait (LOGO)")):
        ax.bar(x + offset, table[column].astype(float), width, label=label)
    labels = [name if stage == "screen" else f"{name} (refined)"
              for name, stage in zip(table["candidate"], table["stage"])]
    ax.set_xticks(x, labels, rotation=30, ha="right", fontsize=8)
    values = table[["train_objective", "validate_objective", "logo_objective"]].to_numpy(float)
    if (values[np.isfinite(values)] > 0).any():
        ax.set_yscale("log")
    ax.set_ylabel("trajectory objective (mean squared residual / σ²)")
    settings = cli.run_settings(csv_path)
    ax.set_title("model selection, ranked by the held-out error"
                 + (f"\n{settings}" if settings else ""), fontsize=9)
    ax.legend(fontsize=8)
    return cli.save_figure(fig, png_path, dpi=120)
