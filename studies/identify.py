"""Model identification shared by `calibrate` and `sensitivity`: parameter boxes mapped from the
unit cube, and the calibration objective evaluated over them.

A box is a list of `ParameterRange` (a StarParams field, its bounds, linear or log). Optimisers
and samplers work in unit coordinates u ∈ [0, 1] per axis; a parameter value is always computed
from u by `ParameterRange.values` (an interpolation between the bounds, clipped to them), never
as a leftover of a subtraction, so a value is in its range by construction::

    from studies.identify import parse_range_spec
    box = [parse_range_spec("alpha=0.2:1.5"), parse_range_spec("cylinder_drag=1:100:log")]
    box[1].values([0.0, 0.5, 1.0])          # -> [1, 10, 100]

The objective (`taichi_star.experiment.objective_values`, with `measurement_table`) is the
library's; this module evaluates it over boxes of points.
"""

from __future__ import annotations

import ast
import dataclasses
import difflib
import math
import re
import sys
from dataclasses import dataclass
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from taichi_star import PER_ACTUATOR_FIELDS, STAR_RANGES, Gait, StarParams, identification
from taichi_star.batch import run_batch
from taichi_star.experiment import PAPER_GAITS, objective_values

from . import cli

DEFAULT_MAX_GENERATIONS = 20
MAX_RESTARTS = 10
"""The most CMA-ES restarts: each doubles the population (IPOP), the last's is 2^10 times the
first's; more is work that cannot finish (and overflows the run-time estimate)."""
FAILED_PENALTY = 1e6
"""Objective told to an optimiser for a failed candidate: CMA-ES needs finite values, and the
gradient fits get it with a zero gradient (the CSVs keep inf)."""
RECORD_INTERVAL_S = 0.01
"""Centroid records of a simulated path that is fitted to or read like the measured tracks
(model_select's and gradient_fit's fits, the strokes read off a path), s: a whole number of
any preset's steps (the fits round it to their --dt's), at least 4 per sample of a cycle
curve, under a video frame (16.7 ms)."""
TOPOLOGY_FIELDS = ("n_arc", "n_limb")
"""Integer fields fixing the topology (shared by a batch): not fittable."""


@dataclass(frozen=True)
class ParameterRange:
    """One StarParams field varied over [low, high], uniformly in the value or (log) in its
    logarithm. Unit coordinate u = 0 is `low`, u = 1 is `high`. `index` (1-based): the axis is
    one element of a tuple-valued field (e.g. a per-actuator gain, index 4 = actuator A4),
    written NAME[INDEX] on the command line."""

    name: str
    low: float
    high: float
    log: bool = False
    index: Optional[int] = None

    def values(self, unit) -> np.ndarray:
        """Parameter values at unit coordinates (any shape; clipped to [0, 1]): the weighted
        mean (1 − u)·low + u·high (of the logarithms when `log`). The bounds themselves are
        returned exactly at u = 0 and 1 (exp(log(x)) need not round back to x) and rounding
        in between is clipped into [low, high]."""
        unit = np.clip(np.asarray(unit, dtype=np.float64), 0.0, 1.0)
        if self.log:
            value = np.exp((1.0 - unit) * math.log(self.low) + unit * math.log(self.high))
        else:
            value = (1.0 - unit) * self.low + unit * self.high
        value = np.where(unit == 0.0, self.low, np.where(unit == 1.0, self.high, value))
        return np.clip(value, self.low, self.high)

    def unit(self, value: float) -> float:
        """The unit coordinate of a value, clipped to [0, 1] (a value outside the box maps to
        its nearest bound)."""
        if self.log:
            u = (math.log(value) - math.log(self.low)) / (math.log(self.high) - math.log(self.low)) \
                if value > 0 else 0.0
        else:
            u = (value - self.low) / (self.high - self.low)
        return float(min(1.0, max(0.0, u)))

    def value_per_unit(self, value) -> float:
        """d value / d u at `value`: high − low, or value·ln(high / low) on a log axis (the
        scale between unit coordinates and the parameter's, for gradients and spreads)."""
        return value * math.log(self.high / self.low) if self.log else self.high - self.low

    @property
    def key(self) -> str:
        """The axis' name in table columns: the field's name, with _INDEX for an element."""
        return self.name if self.index is None else f"{self.name}_{self.index}"

    @property
    def label(self) -> str:
        """The axis as written on the command line: NAME or NAME[INDEX]."""
        return self.name if self.index is None else f"{self.name}[{self.index}]"

    @property
    def sensitivity_name(self) -> str:
        """The axis as `simulate(sensitivities=...)` names it: NAME, or NAME[INDEX − 1] for an
        element (the sensitivities take Python's index, the command line the actuator's
        number)."""
        return sensitivity_name(self.label)

    @property
    def column(self) -> str:
        """The table column of the parameter's values (its name with its unit, e.g.
        joint_radius_m; _INDEX appended for an element)."""
        column = StarParams.columns()[self.name]
        return column if self.index is None else f"{column}_{self.index}"

    @property
    def spec(self) -> str:
        """The range as written on the command line, e.g. "cylinder_drag=1:100:log"."""
        return f"{self.label}={self.low:g}:{self.high:g}" + (":log" if self.log else "")

    def value_of(self, params: StarParams) -> float:
        """The axis' value in a model."""
        value = getattr(params, self.name)
        return float(value if self.index is None else value[self.index - 1])


def parse_range_spec(text: str, flag: str = "--fit") -> ParameterRange:
    """"NAME=LOW:HIGH" or "NAME=LOW:HIGH:log" -> ParameterRange, checked against the field's valid
    range (`check_field_range`). StudyArgumentError naming the flag and field when malformed."""
    if "=" not in str(text):
        raise cli.StudyArgumentError(f"{flag}: expected NAME=LOW:HIGH[:log] (e.g. "
                                     f"alpha=0.2:1.5), got {text!r}")
    name, bounds = text.split("=", 1)
    name = name.strip().replace("-", "_")
    index = None
    if name.endswith("]") and "[" in name:
        name, element = name[:-1].split("[", 1)
        try:
            index = int(element)
        except ValueError:
            raise cli.StudyArgumentError(f"{flag} {name}: element [{element}] is not an "
                                         f"integer (NAME[INDEX], INDEX from 1)") from None
    parts = [p.strip() for p in bounds.split(":")]
    if len(parts) not in (2, 3) or (len(parts) == 3 and parts[2].lower() != "log"):
        raise cli.StudyArgumentError(f"{flag} {name}: malformed bounds {bounds!r}; expected "
                                     f"LOW:HIGH or LOW:HIGH:log (e.g. 1:100:log)")
    low = cli.parse_number(parts[0], f"{flag} {name}")
    high = cli.parse_number(parts[1], f"{flag} {name}")
    spec = ParameterRange(name, low, high, log=len(parts) == 3, index=index)
    check_field_range(spec, flag)
    return spec


def fittable_fields() -> List[str]:
    """The fields a box may vary: the real-valued ones but the topology's, and the per-actuator
    ones element by element (NAME[INDEX])."""
    return [*(name for name in StarParams.numeric_field_names() if name not in TOPOLOGY_FIELDS),
            *(f"{name}[INDEX]" for name in PER_ACTUATOR_FIELDS)]


def check_field_range(spec: ParameterRange, flag: str):
    """StudyArgumentError naming `flag` and the field (an unknown one with the closest
    `fittable_fields`) unless the field is a real-valued StarParams field, LOW < HIGH, both
    finite and inside the field's valid range, and LOW > 0 for a log axis. An element axis
    (NAME[INDEX]) needs a tuple-valued field and an INDEX within it; its range is checked by
    the model's own validation (`check_box`)."""
    if spec.name not in StarParams.field_names():
        close = difflib.get_close_matches(spec.name, fittable_fields(), n=3)
        hint = (f"did you mean {', '.join(close)}?" if close
                else f"fittable fields: {', '.join(fittable_fields())}")
        raise cli.StudyArgumentError(f"{flag}: unknown parameter {spec.name!r}; {hint}")
    kind = cli.field_kind(spec.name)
    where = f"{flag} {spec.label}"
    if spec.index is not None:
        default = getattr(StarParams(), spec.name)
        if not isinstance(default, tuple):
            raise cli.StudyArgumentError(f"{where}: {spec.name} is not a tuple-valued field "
                                         f"(give it without [INDEX])")
        if not 1 <= spec.index <= len(default):
            raise cli.StudyArgumentError(f"{where}: INDEX must be in [1, {len(default)}]")
    elif kind is not float or spec.name in TOPOLOGY_FIELDS or spec.name not in STAR_RANGES:
        raise cli.StudyArgumentError(f"{where}: not a real-valued numeric field (fix it with "
                                     f"--set); fittable fields: "
                                     f"{', '.join(fittable_fields())}")
    if not (math.isfinite(spec.low) and math.isfinite(spec.high)):
        raise cli.StudyArgumentError(f"{where}: bounds must be finite, got "
                                     f"{spec.low}:{spec.high}")
    if not spec.low < spec.high:
        raise cli.StudyArgumentError(f"{where}: reversed or empty bounds {spec.low:g}:"
                                     f"{spec.high:g} (need LOW < HIGH)")
    if spec.log and spec.low <= 0:
        raise cli.StudyArgumentError(f"{where}: a log axis needs LOW > 0, got {spec.low:g}")
    if spec.index is not None:
        return
    lowest, highest, included = STAR_RANGES[spec.name]
    if spec.low < lowest or (spec.low == lowest and not included) or spec.high > highest:
        span = f"[{lowest:g}, {highest:g}]" if included else f"({lowest:g}, {highest:g}]"
        raise cli.StudyArgumentError(f"{where}: bounds {spec.low:g}:{spec.high:g} leave the "
                                     f"field's valid range {span}")


def check_box(box: Sequence[ParameterRange], base: StarParams, flag: str = "--fit"):
    """Check a whole box before any compute: at least one axis, each a valid range of a
    real-valued field (`check_field_range`), no field twice, and every corner
    a valid StarParams on top of `base` (catches limits between fields, e.g. tip_radius >
    joint_radius). StudyArgumentError naming the flag and the field."""
    if not box:
        raise cli.StudyArgumentError(f"{flag}: no parameters to vary")
    labels = [spec.label for spec in box]
    for spec in box:
        check_field_range(spec, flag)
        if labels.count(spec.label) > 1:
            raise cli.StudyArgumentError(f"{flag} {spec.label}: given twice")
    for corner in range(2 ** len(box)):
        values = [spec.high if corner >> axis & 1 else spec.low for axis, spec in enumerate(box)]
        point = point_changes(box, values, base)
        try:
            base.replace(**point)
        except (ValueError, TypeError) as error:
            raise cli.StudyArgumentError(f"{flag}: the corner {point} of the box is not a "
                                         f"valid robot: {error}") from None


def model_with_box(args, box: Sequence[ParameterRange], flag: str) -> StarParams:
    """The model of --preset and --set on which the box (given by `flag`, e.g. --fit) is varied,
    checked with the box (`check_box`). StudyArgumentError naming --set for a field that is
    both set and in the box, or for a field the study sets itself."""
    in_box = {spec.name for spec in box}
    for item in args.set:
        name, _ = cli.parse_assignment(item, "--set")
        if name in in_box:
            raise cli.StudyArgumentError(f"--set {name}: fitted or varied by {flag} as well "
                                         f"(fix it or vary it, not both)")
    base = cli.base_params(args)
    check_box(box, base, flag)
    return base


def box_values(box: Sequence[ParameterRange], unit_points) -> np.ndarray:
    """Unit points (P, D) -> parameter values (P, D), column d from box[d]."""
    unit_points = np.atleast_2d(np.asarray(unit_points, dtype=np.float64))
    return np.column_stack([spec.values(unit_points[:, d]) for d, spec in enumerate(box)])


def box_value_per_unit(box: Sequence[ParameterRange], values) -> np.ndarray:
    """d value / d u of every axis (D,) at the point's values (D,)
    (`ParameterRange.value_per_unit`)."""
    return np.array([spec.value_per_unit(value) for spec, value in zip(box, values)])


def box_params(box: Sequence[ParameterRange], values, base: StarParams,
               gaits: Sequence[str]) -> List[StarParams]:
    """One StarParams per (point, gait), point-major: values (P, D) -> P × len(gaits) robots."""
    return [base.replace(gait=gait, **point_changes(box, point, base))
            for point in np.atleast_2d(values) for gait in gaits]


def point_changes(box: Sequence[ParameterRange], values, base: StarParams) -> dict:
    """{field: value} of one point of the box (values (D,)): scalar axes as floats, element
    axes assembled into their field's tuple on top of the base model's."""
    changes = {}
    for spec, value in zip(box, values):
        if spec.index is None:
            changes[spec.name] = float(value)
        else:
            elements = list(changes.get(spec.name, getattr(base, spec.name)))
            elements[spec.index - 1] = float(value)
            changes[spec.name] = tuple(elements)
    return changes


# --------------------------------------------------------------------------- CMA-ES

@dataclasses.dataclass(frozen=True)
class CMASettings:
    """CMA-ES settings: popsize None = cma's default 4 + ⌊3 ln D⌋ (doubled at each restart),
    sigma0 = initial step in unit coordinates, seed ≥ 0 (the run is reproducible)."""
    popsize: Optional[int] = None
    max_generations: int = DEFAULT_MAX_GENERATIONS
    restarts: int = 0
    seed: int = 1
    sigma0: float = 0.25

    def validate(self):
        """StudyArgumentError naming the flag of an invalid setting."""
        if self.popsize is not None and self.popsize < 2:
            raise cli.StudyArgumentError(f"--popsize must be >= 2, got {self.popsize}")
        if self.max_generations < 1:
            raise cli.StudyArgumentError(f"--max-generations must be >= 1, got "
                                            f"{self.max_generations}")
        if self.restarts < 0:
            raise cli.StudyArgumentError(f"--restarts must be >= 0, got {self.restarts}")
        if self.restarts > MAX_RESTARTS:
            raise cli.StudyArgumentError(f"--restarts must be <= {MAX_RESTARTS} (each doubles "
                                         f"the population), got {self.restarts}")
        if self.seed < 0:
            raise cli.StudyArgumentError(f"--seed must be >= 0, got {self.seed}")
        if not (math.isfinite(self.sigma0) and 0 < self.sigma0 <= 1):
            raise cli.StudyArgumentError(f"--sigma0 must be in (0, 1] (unit coordinates), got "
                                            f"{self.sigma0}")

    def population(self, dimension: int, restart: int) -> int:
        return (self.popsize or 4 + int(3 * math.log(dimension))) * 2 ** restart

    def evaluations(self, dimension: int) -> int:
        """The most evaluations a fit of `dimension` axes makes: every generation of every
        restart."""
        return sum(self.max_generations * self.population(dimension, restart)
                   for restart in range(self.restarts + 1))


def _cma_seed(seed: int, restart: int) -> int:
    # cma treats seed 0 as "randomise": derive a positive seed per (seed, restart)
    return int(np.random.SeedSequence([seed, restart]).generate_state(1)[0]) % (2 ** 31 - 2) + 1


@dataclass
class CMAResult:
    """What `minimise_cmaes` returns: every evaluation (columns evaluation, restart,
    generation, candidate, then those of the evaluate callable, which must include
    "objective"), and the search distribution's standard deviation per axis in unit
    coordinates (σ·√diag C of the restart that found the best point, when it stopped): a scale
    of how well the data pin each axis down near the optimum, not a posterior; and per restart
    why it stopped (cma's termination conditions, e.g. "maxiter=8")."""
    evaluations: pd.DataFrame
    unit_std: np.ndarray
    stop_reasons: List[str]


def read_start(path, base: StarParams, set_fields: Sequence[str] = ()) -> StarParams:
    """--start: the model of an earlier run's identified.csv (columns field and value, the value
    as Python text; model_select writes it) on top of `base`; StudyArgumentError naming --start
    for a file that cannot be read, a field StarParams does not have, a value out of its
    range, or a field among `set_fields` (what --set gave `base`: the file's value would
    replace it without a word)."""
    table = cli.read_csv_file(path, "--start", dtype=str, keep_default_na=False)
    missing = {"field", "value"} - set(table.columns)
    if missing or not len(table):
        raise cli.StudyArgumentError(f"--start {path}: not an identified.csv (rows of field, "
                                     f"value; no column(s) {', '.join(sorted(missing))})"
                                     if missing else f"--start {path}: no rows")
    known = set(StarParams.field_names())
    fields = {}
    for name, text in zip(table["field"], table["value"]):
        if name not in known or name == "gait":
            raise cli.StudyArgumentError(f"--start {path}: {name!r} is not a model field")
        try:
            fields[name] = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            raise cli.StudyArgumentError(f"--start {path}: {name} = {text!r} is not a "
                                         f"value") from None
        if name in set_fields:
            raise cli.StudyArgumentError(f"--start {path} sets {name}, which --set gives too: "
                                         f"give it in one of them")
    try:
        return base.replace(**fields)
    except (ValueError, TypeError) as error:
        raise cli.StudyArgumentError(f"--start {path}: {error}") from None


def start_units(box: Sequence[ParameterRange], base: StarParams) -> np.ndarray:
    """Unit coordinates (D,) of the base model's values (clipped into the box)."""
    return np.array([spec.unit(spec.value_of(base)) for spec in box])


def minimise_cmaes(box: Sequence[ParameterRange], start, evaluate: Callable[[np.ndarray],
                   pd.DataFrame], settings: CMASettings = CMASettings(), progress: bool = False,
                   on_generation: Callable[[pd.DataFrame], None] = None) -> CMAResult:
    """Minimise over the box's unit cube with CMA-ES (ask/tell, cma's bound handling): the
    first run from `start` (D,) with step settings.sigma0, each restart from a uniformly random
    point with twice the population (IPOP), seeded from settings.seed. `evaluate(units (P, D))`
    scores one generation (one batched simulation) and returns a table with one row per point
    and an "objective" column (inf for a failed point: CMA-ES is told FAILED_PENALTY).
    `on_generation(table so far)` is called after each generation (e.g. to write the CSV)."""
    import cma
    if not box:
        raise cli.StudyArgumentError("--fit: no parameters to vary")
    settings.validate()
    dimension = len(box)
    start = np.asarray(start, dtype=np.float64)
    parts: List[pd.DataFrame] = []
    spreads: List[np.ndarray] = []
    stop_reasons: List[str] = []
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=settings.max_generations * (settings.restarts + 1), unit="generation",
                   desc="CMA-ES")
    for restart in range(settings.restarts + 1):
        rng = np.random.default_rng([settings.seed, restart])
        x0 = start if restart == 0 else rng.uniform(0.0, 1.0, dimension)
        es = cma.CMAEvolutionStrategy(list(x0), settings.sigma0, {
            "bounds": [0.0, 1.0], "popsize": settings.population(dimension, restart),
            "seed": _cma_seed(settings.seed, restart), "maxiter": settings.max_generations,
            "verbose": -9})
        generation = 0
        while not es.stop():
            candidates = es.ask()
            table = evaluate(np.asarray(candidates))
            values = table["objective"].to_numpy()
            es.tell(candidates, list(np.where(np.isfinite(values), values, FAILED_PENALTY)))
            table.insert(0, "candidate", np.arange(len(table)))
            table.insert(0, "generation", generation)
            table.insert(0, "restart", restart)
            parts.append(table)
            generation += 1
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=f"{min(p['objective'].min() for p in parts):.4g}")
            if on_generation is not None:
                on_generation(_numbered(parts))
        spreads.append(es.sigma * np.sqrt(np.diag(es.C)))
        stop_reasons.append(", ".join(f"{name}={value}" for name, value in es.stop().items()))
        if bar is not None:  # an early stop leaves generations of this run unused
            bar.total -= settings.max_generations - generation
            bar.refresh()
    if bar is not None:
        bar.close()
    evaluations = _numbered(parts)
    best = best_row(evaluations)
    restart = int(best["restart"]) if best is not None else 0
    return CMAResult(evaluations, spreads[restart], stop_reasons)


def _numbered(parts: List[pd.DataFrame]) -> pd.DataFrame:
    table = pd.concat(parts, ignore_index=True)
    table.insert(0, "evaluation", np.arange(len(table)))
    return table


def best_row(evaluations: pd.DataFrame) -> Optional[pd.Series]:
    """The evaluation with the smallest finite objective (the first of ties), or None."""
    finite = evaluations[np.isfinite(evaluations["objective"].astype(float))]
    return None if finite.empty else finite.loc[finite["objective"].idxmin()]


def best_units(evaluations: pd.DataFrame, box) -> np.ndarray:
    """Unit coordinates (D,) of the best evaluation (`best_row`: one with a finite objective
    must be there) in the box's D axes (its u_KEY columns)."""
    row = best_row(evaluations)
    return np.array([row[f"u_{spec.key}"] for spec in box], dtype=float)


# --------------------------------------------------------------------------- the objective

def measured_gaits(text: str, flag: str = "--gaits") -> List[str]:
    """`--gaits` ("paper" or a comma list) -> canonical gait names, each one of the measured
    `PAPER_GAITS`; StudyArgumentError naming the flag for an empty list, an unmeasured gait or a
    gait listed twice."""
    gaits = cli.resolve_gaits(text, flag)
    for gait in gaits:
        if gait not in PAPER_GAITS:
            raise cli.StudyArgumentError(f"{flag} {gait}: not measured; the measured gaits are "
                                         f"{', '.join(PAPER_GAITS)}")
    return gaits


def unfired_axes(box: Sequence[ParameterRange], gaits: Sequence[str]) -> List[str]:
    """Labels of the box's per-actuator axes (NAME[k]) whose actuator A_k none of `gaits`
    fires: nothing those gaits do depends on them (their derivatives are exactly zero), so no
    fit to those gaits can identify them."""
    fired = {actuator for gait in gaits for actuator in Gait.parse(gait).actuators}
    return [axis.label for axis in box
            if axis.name in PER_ACTUATOR_FIELDS and axis.index not in fired]


def check_unfired_axes(study: str, what: str, box: Sequence[ParameterRange],
                       gaits: Sequence[str]):
    """Name on stderr, before a fit starts, the box's axes that the fitted gaits cannot move
    (`unfired_axes`); `what` names the box ("--fit", "set 20"). A box of such axes alone is
    refused (StudyArgumentError): its objective is flat, nothing to fit (and cma's bound
    handling fails on a flat objective in one dimension, a traceback: an audit, 2026-12)."""
    idle = unfired_axes(box, gaits)
    if idle and len(idle) == len(box):
        raise cli.StudyArgumentError(f"{what}: {', '.join(idle)}: no fitted gait fires "
                                     f"{'its actuator' if len(idle) == 1 else 'their actuators'}"
                                     f" ({', '.join(gaits)}), so the fit depends on none of "
                                     f"its parameters")
    if idle:
        one = len(idle) == 1
        print(f"{study}: note: {what}: {', '.join(idle)} "
              f"{'belongs to an actuator' if one else 'belong to actuators'} that no fitted gait "
              f"fires ({', '.join(gaits)}): the fit does not depend on "
              f"{'it' if one else 'them'} and cannot identify {'it' if one else 'them'}",
              file=sys.stderr)


def parse_windows(train_text: str, validate_text: str) -> Tuple[Tuple[int, int], Tuple[int, int]]:
    """--train-cycles and --validate-cycles ("FIRST:LAST", 1 <= FIRST <= LAST <= the library's
    MAX_CYCLE) -> the two windows; StudyArgumentError naming the flag for a malformed window or
    a validation window that does not start after the training one."""
    windows = []
    for text, flag in ((train_text, "--train-cycles"), (validate_text, "--validate-cycles")):
        parts = str(text).split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            windows.append(identification.check_window(tuple(int(p) for p in parts)))
        except ValueError:
            raise cli.StudyArgumentError(
                f"{flag}: expected FIRST:LAST cycle numbers with 1 <= FIRST <= LAST <= "
                f"{identification.MAX_CYCLE}, got {text!r}") from None
    if windows[1][0] <= windows[0][1]:
        raise cli.StudyArgumentError(f"--validate-cycles {validate_text}: must start after the "
                                     f"training window {train_text}")
    return windows[0], windows[1]


def sensitivity_name(label: str) -> str:
    """A box axis's command-line label (NAME, or NAME[INDEX] with the actuator's number,
    `ParameterRange.label`) as `simulate(sensitivities=...)` names it (NAME[INDEX − 1],
    `ParameterRange.sensitivity_name`); any other text as it is."""
    match = re.fullmatch(r"(\w+)\[(\d+)\]", str(label))
    return f"{match[1]}[{int(match[2]) - 1}]" if match else str(label)


def check_trials_cover(trials, window: Tuple[int, int], window_text: str,
                       flag: str = "--validate-cycles"):
    """StudyArgumentError naming `flag` (the window's: by default --validate-cycles, the later
    of the two windows) unless every measured trial (`identification.Trial`s) covers the
    window from every phase of a period: the phase fitted on the earlier window may be any,
    and a window the trial covered only for early phases failed after the whole fit (an
    audit, 2026-12: A1+A3's cycles 13-15 only up to 0.21 s)."""
    for trial in trials.values():
        try:
            latest = identification.latest_phase(trial, window)
        except ValueError as error:
            raise cli.StudyArgumentError(f"{flag} {window_text}: {error}") from None
        period, end = trial.path.period_s, trial.path.t_s[-1]
        if latest < period:
            raise cli.StudyArgumentError(
                f"{flag} {window_text}: the {trial.gait} trial ({end:g} s) covers these cycles "
                f"only from a phase up to {latest:.3g} s, not from every phase of its "
                f"{period:g}-s period; its windows end at cycle {math.floor(end / period) - 1} "
                f"at the latest")


def evaluate_points(box: Sequence[ParameterRange], unit_points, base: StarParams,
                    measurements: pd.DataFrame, run_kwargs: dict) -> pd.DataFrame:
    """Simulate every point of the box on every gait of `measurements` in one batched run
    (`taichi_star.batch.run_batch` with `run_kwargs`: run length, solver, arch, executor,
    chunk size) and return one row per point: u_<name> (unit coordinates), <name>
    (values), objective, n_direction_mismatches, mismatched_gaits, status (the first non-ok
    status, else "ok"), failed_gaits (each failed gait with its status and simulated time,
    "A1+A2 newton_failed at 1.23 s", ";"-separated; empty when none failed), then
    signed_speed_<gait> and speed_<gait> in mm/s."""
    unit_points = np.atleast_2d(np.asarray(unit_points, dtype=np.float64))
    gaits = list(measurements.index)
    values = box_values(box, unit_points)
    summary = run_batch(box_params(box, values, base, gaits), **run_kwargs).summary
    shape = (len(unit_points), len(gaits))
    status = summary["status"].to_numpy().reshape(shape)
    ok = status == "ok"
    signed = np.where(ok, summary["signed_speed_mm_s"].to_numpy(dtype=float).reshape(shape),
                      np.nan)
    speed = np.where(ok, summary["speed_mm_s"].to_numpy(dtype=float).reshape(shape), np.nan)
    wrong = ok & (np.sign(signed) != measurements["paper_sign"].to_numpy())
    table = pd.DataFrame({f"u_{s.key}": unit_points[:, d] for d, s in enumerate(box)})
    for d, spec in enumerate(box):
        table[spec.column] = values[:, d]
    table["objective"] = objective_values(signed, measurements)
    table["n_direction_mismatches"] = wrong.sum(axis=1)
    table["mismatched_gaits"] = [" ".join(np.asarray(gaits)[row]) for row in wrong]
    table["status"] = [next((s for s in row if s != "ok"), "ok") for row in status]
    # which gait failed, and when: the status alone named neither (an audit, 2026-12)
    failure_times = summary["failure_time_s"].to_numpy(dtype=float).reshape(shape)
    table["failed_gaits"] = ["; ".join(f"{gait} {s} at {t:.4g} s"
                                       for gait, s, t in zip(gaits, row, times) if s != "ok")
                             for row, times in zip(status, failure_times)]
    for g, gait in enumerate(gaits):
        table[f"signed_speed_{gait}"] = signed[:, g]
    for g, gait in enumerate(gaits):
        table[f"speed_{gait}"] = speed[:, g]
    return table
