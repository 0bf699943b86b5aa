"""Gradient-based identification beside CMA-ES: L-BFGS-B on the exact gradient of the
trajectory objective, a trust-region least-squares fit and Levenberg-Marquardt in batches on
the exact (or Broyden-updated) Jacobian of its residuals, against CMA-ES on the same
objective, box and start, for two parameter sets.

    python -m studies gradient_fit [--sets 6,20fired] [--gaits paper|A1,A1+A2,...]
                                   [--train-cycles 1:3] [--validate-cycles 4:6]
                                   [--starts 2] [--lbfgs-evaluations 8]
                                   [--least-squares-evaluations 8]
                                   [--broyden-evaluations 16]
                                   [--lm-iterations 4] [--lm-batch 7]
                                   [--lm-broyden-iterations 4] [--lm-broyden-batch 3]
                                   [--least-squares-method trf|dogbox]
                                   [--cma-generations 8] [--polish-evaluations 0]
                                   [--popsize P] [--sigma0 0.25] [--seed S]
                                   [--start IDENTIFIED_CSV] [--held-out-gaits GAITS]
                                   [--preset paper|accurate] [--set NAME=VALUE ...] [--dt S]
                                   [--arch cpu|gpu] [--out DIR] [--quick]

The objective is `taichi_star.identification`'s trajectory objective on the training window
(`--train-cycles`), every gait's phase fitted as a nuisance. The box is in unit coordinates
(`studies.identify.ParameterRange`: `:log` axes in the logarithm, as the CMA-ES studies fit
them). Every optimiser starts at --preset/--set's model, or with `--start` at an earlier
model_select run's identified point (to compare the optimisers on continuing a fit; a field
both give is refused), clipped into the box (a note on stderr names the axes where the model
lies outside it: set "20fired" starts the delays of A3-A5, 0 in the presets, at 0.0005 s).
Before anything runs, the step is checked against the windows the study simulates and the
instances of all sets together against the limit, their robot-steps estimated. Sets: "6",
the six axes of `calibrate` (α, rod added mass, C⊥, C∥, C_c, limb stiffness);
"20", those six, the eight actuator gains and six more per-robot fields (hub added mass,
Young's modulus, the two densities, hub mass per height, thickness); "20fired", twenty that the
measured gaits can all move (the six, the gains of A1-A5, the delays of A2-A4, the six
per-robot fields: no measured gait fires A6-A8, so their gains have zero derivatives);
"gains_with_a1", the eight axes of the `identified` preset's form (α, C⊥, C_c, the gains of
A1-A5).

- L-BFGS-B (scipy, bounds [0, 1] per axis) gets the objective and its gradient from one run
  with sensitivities (`simulate(..., sensitivities=...)`, `identification.objective_and_gradient`,
  chain rule through the box's map u -> value); `--starts` starts: the base model, then uniform
  random points (seeded); each stops at `--lbfgs-evaluations` evaluations or when it stalls.
- least squares (scipy's `least_squares`, `--least-squares-method` trf or dogbox, same bounds
  and starts): the objective is a sum of squares (`identification.objective_residuals`: the
  curve residuals and ρ of every gait), and a run with sensitivities gives the residuals'
  Jacobian and a Gauss-Newton step; a start's first point is a run with sensitivities, every
  later trial point a run without, the Jacobian a run with them at the points scipy accepts;
  `--least-squares-evaluations` trial points per start (0: not run).
- least squares with Broyden's updates ("least-squares-broyden", `--broyden-evaluations` trial
  points per start, 0: not run): the same fit, whose Jacobian is simulated at each start and
  then only where the last one (simulated or updated) served badly (a step refused since, or a
  step that achieved less than `SECANT_AGREEMENT` of its predicted reduction), and elsewhere
  updated by Broyden's rank-one rule from the step and the change of the residuals its trial
  point's run gave: most of its points cost one run.
- Levenberg-Marquardt in batches ("levenberg-marquardt-batch", `--lm-iterations` batches per
  start, 0: not run): at each accepted point one run with sensitivities gives the residuals'
  Jacobian, and one batched run without them scores `--lm-batch` damped steps from it at once
  (dampings a decade apart, the box-constrained Levenberg-Marquardt step for each,
  `damped_steps`); the best that improves is taken and the next grid centred on its damping.
  Where a trust-region fit spends a run (and, on a shoulder, a Jacobian) on each step length
  it tries, this one tries a grid of them per Jacobian, in one call of the batch simulator.
  Same starts and bounds as the others; a batch counts every point's robot-seconds, all on its
  first row.
- Levenberg-Marquardt in batches with Broyden's updates ("levenberg-marquardt-broyden",
  `--lm-broyden-iterations` batches per start, 0: not run): the same batches, each scoring its
  points' residuals too, whose Jacobian is simulated at the start and then only where the last
  one served badly (as the secant least-squares fit's: `secant_jacobian`), elsewhere
  Broyden-updated along the step taken; a start's first batch has `--lm-batch` points, the
  later ones `--lm-broyden-batch` (default 3: one decade either way of the damping that
  served).
- CMA-ES (`studies.identify.minimise_cmaes`) from the base model, step `--sigma0`, population
  `--popsize` (cma's default 4 + 3 ln D when not given), `--cma-generations` generations, one
  batched run per generation.
- CMA-ES + least squares (`--polish-evaluations`, off by default): the least-squares fit from
  CMA-ES's best point, its rows' costs and wall time counted on top of CMA-ES's whole run (a
  global search, then Gauss-Newton steps to polish its result).

A run with sensitivities leaves out the per-actuator axes of actuators no fitted gait fires
(their derivatives are exactly zero; `Problem.moved_names`), and the gradient fits search the
other axes alone (the left-out ones held at the start's values; CMA-ES searches every axis):
the study names them on stderr before it starts.

Cost, per optimiser: evaluations (a CMA-ES point; an L-BFGS-B call; a least-squares fit's
runs, with and without sensitivities; each point of a Levenberg-Marquardt batch and each of
its Jacobians), wall time, and simulated robot-seconds = instances ×
simulated seconds, counted two ways. A run with n sensitivities carries 2n replica instances
per instance (the ±ε pairs): they are never solved, only assembled at the solved state, so
they cost less than an instance; `robot_seconds` counts each replica as a full instance
((1 + 2n) × gaits × window), the
conservative count, and `robot_seconds_cost_equivalent` counts a call as `gradient_cost_ratio`
runs: the wall time of the call's simulation (with the n sensitivities) over that of the same
simulation without, measured in this run at the base point (`measure_cost_ratio`; column
`gradient_cost_ratio`). CMA-ES counts gaits × window per point.

Writes into --out (default runs/gradient_fit/<timestamp>/), each CSV with its provenance
sidecar: `gradient_fit.csv` (per set and optimiser: the cost columns, objective reached,
validation objective on `--validate-cycles` with the training phases, robot-seconds each
gradient fit needed to reach CMA-ES's objective and their ratio to CMA-ES's total, both counts,
the best objective each optimiser reached within CMA-ES's cost-equivalent robot-seconds
(`objective_at_cma_cost`: the optimisers compared on one budget; for the polish, whose costs
count on top of CMA-ES's run, CMA-ES's best), and `stop_reasons`: why
each start or restart ended, in its library's words, or that a least-squares start spent its
trial points), `gradient_fit_cma_budgets.csv` (`cma_budget_shares`: against CMA-ES's best
after each of its generations, the cost-equivalent robot-seconds each other optimiser needed to
reach it and their share of CMA-ES's: the comparison for every CMA-ES budget up to
--cma-generations; drawn in `gradient_fit_cma_budgets.png`), `gradient_fit_history.csv` (every
evaluation: cumulative cost and best objective so far), `gradient_fit_uncertainty.csv` (per
set, optimiser and parameter, at the optimiser's best point:
`identification.parameter_uncertainty` from one run with the sensitivities there, not counted
in any cost: which parameters the training data determine, their standard errors and
correlations), `gradient_fit.png` (best objective against robot-seconds, drawn from the
history), `gradient_fit_segments.csv` and its plot
`gradient_fit_segments.png` (per set, the objective and each gait's along the straight segment
from each optimiser's best point to the set's lowest, `segment_scores`: whether a fit that
stopped higher stopped in another valley, one batched run not counted in any cost) and, with
`--held-out-gaits` (measured gaits that no
optimiser fits), `gradient_fit_held_out.csv`: per set, the start point and every optimiser's
best point scored on each held-out gait's training window, its phase fitted there (as
model_select's leave-one-gait-out folds score the gait they hold out), one row per point and
gait with `identification.trial_fit`'s columns: whether what the fits did to the point carries
over to a gait they did not see. The start itself is not held out from anything: a start taken
from a fit that saw the gait (`--start`) tests the optimisers' moves, not the start.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path
from typing import List, Optional, Sequence, Tuple

import numpy as np
import pandas as pd

from taichi_star import identification, simulate
from taichi_star.profiling import interleaved_rounds
from taichi_star.sensitivities import REPLICAS_PER_DIRECTION, instances_per_instance
from taichi_star.timegrid import nearest_interval

from . import cli, identify
from .optimise import minimise_lbfgsb

DESCRIPTION = ("L-BFGS-B, least squares and Levenberg-Marquardt in batches on the exact "
               "gradient of the trajectory objective beside CMA-ES, for 6 and 20 parameters: "
               "evaluations, robot-seconds, wall time, objective reached.")

PARAMETER_SETS = {
    "6": ["alpha=0.2:1.5", "added_mass_coeff=0:3", "drag_perpendicular=0.3:3:log",
          "drag_parallel=0.001:0.1:log", "cylinder_drag=1:100:log",
          "limb_stiffness_ratio=10:1000:log"],
}
ROBOT_FIELDS = ["cylinder_added_mass_coeff=0:2", "youngs_modulus=1e6:2.5e7:log",
                "actuator_density=1500:4000", "foam_density=300:1200",
                "cylinder_mass_per_height=0.5:2", "thickness=0.002:0.005"]
"""The twenty-parameter sets' six per-robot fields (hub added mass, Young's modulus, the two
densities, the hub's mass per height, thickness)."""
PARAMETER_SETS["20"] = PARAMETER_SETS["6"] + [
    f"actuator_gains[{k}]=0.3:2" for k in range(1, 9)] + ROBOT_FIELDS
FIRED_ACTUATORS = range(1, 6)
"""The actuators the measured gaits fire (A1-A5: A1, A1+A2, A1+A3, A1+A4, A1+A3+A5)."""
PARAMETER_SETS["gains_with_a1"] = ["alpha=0.2:1.5", "drag_perpendicular=0.3:3:log",
                                   "cylinder_drag=1:100:log"] + [
    f"actuator_gains[{k}]=0.3:2" for k in FIRED_ACTUATORS]
PARAMETER_SETS["20fired"] = PARAMETER_SETS["6"] + [
    f"actuator_gains[{k}]=0.3:2" for k in FIRED_ACTUATORS] + [
    f"actuator_delays[{k}]=0.0005:0.2995" for k in (2, 3, 4)] + ROBOT_FIELDS
"""The fitted boxes by name: calibrate's six axes; "20", six + eight gains + six per-robot
fields; "20fired", twenty that the five measured gaits can all move. Set "20" has the gains of
A6-A8, which no measured gait fires (their derivatives are exactly zero); "gains_with_a1" is
the box of model_select's form of that name (studies/model_candidates.csv), the `identified`
preset's; "20fired" has the
gains of the fired actuators and the firing delays of A2-A4 after A1 (A1's own delay is a
shift of the whole gait, which the fitted phase absorbs; A5 fires only with A3). Both ends of
the delays' box lie half a default step (0.5 ms) off the step grid: a delay on the grid puts
the actuation profile's switch on a step end, where the run jumps as the delay passes and has
no derivative by it (the sensitivities warn), and a fit often ends at a bound."""
DEFAULT_SETS = "6,20fired"
"""The sets a plain run fits."""
CORNER_GROUP = 10
"""Axes whose 2^k corners are checked together (`identify.check_box`): the 20-axis box in two
groups; no limit between fields ties an axis of one group to one of the other."""
COST_REPEATS = 3
"""Interleaved timings of the gradient's simulation and the plain one (`measure_cost_ratio`)."""
LEAST_SQUARES_METHODS = ("trf", "dogbox")
"""scipy `least_squares` methods the fit may use (--least-squares-method). trf (scipy's default,
reflective steps within an elliptic trust region) by default since cb4f234: from the base
model and from the seeded random start, over eight trial points, with the objective's 384-point
phase search, it reached a lower objective than dogbox (a dogleg within a rectangular trust
region that drops axes at a bound) on sets 20 (78.7 against 93.7 after four points from the
base model; 115.4 against 129.3 after eight from the random start) and 20fired (249.2 against
798.2 after eight from the base model, five gaits), and on set 6 it ended lower (50.6 against
51.5) though dogbox's first step went further (63.5 against 411.5); measured at fc798ce with
a scratch script, each start's first point a residual run of its own, and again with this
study at cb4f234 (results/gradient_fit/methods/, docs/results "Least squares by trf"): the
share of CMA-ES's run at which least squares reaches its objective 0.154 (trf) and 0.311
(dogbox) on set 20, 0.101 and 0.043 on set 6, 0.658 and never on 20fired. Until then dogbox,
chosen under the earlier 64-point phase search, where its first step from the base model went
further on sets 20 and 6 (5,550 → 57.5 and → 67.6; trf → 374 and → 412)."""
DEFAULT_LEAST_SQUARES_METHOD = "trf"
LEAST_SQUARES = "least-squares"
"""The least-squares optimiser's name in the tables."""
BROYDEN = "least-squares-broyden"
"""The least-squares fit whose Jacobian is simulated at its start and updated by Broyden's rule
between simulated ones (`fit_least_squares(secant=True)`; --broyden-evaluations)."""
SECANT_AGREEMENT = 0.25
"""The least share of the reduction a step's linear model predicted that the step must achieve
for the secant fit to update its Jacobian by Broyden's rule rather than simulate it (with no
trial point since the last Jacobian, simulated or updated, scoring no better than its point):
trust-region methods' usual threshold of a poor model (scipy's trf shrinks its region below
it)."""
LEVENBERG_MARQUARDT = "levenberg-marquardt-batch"
"""Levenberg-Marquardt with a batch of damped steps per Jacobian
(`fit_levenberg_marquardt`; --lm-iterations)."""
MARQUARDT_DAMPING = 0.01
"""The damping the batches' grid of dampings is first centred on: Marquardt's own first λ
(1963), the damping relative to each axis's curvature (the steps' scaling, `damped_steps`)."""
DEFAULT_LM_BATCH = 7
"""Damped steps per batch (--lm-batch; the Broyden-updated fit's first batch): dampings a
decade apart, three either way of the centre, the only width tried for the batches with a
Jacobian at each accepted point (scratch runs of the Broyden-updated fit, 2026-12, tried 5 and
7 for its first and 3, 5 and 7 for its later batches). In the committed runs of
results/gradient_fit/lm_batch/equal_cost/ and broyden/ (2026-12) the best damping of 9 of 51
distinct batches lay at an end of its grid, 4 at the longest step and 5 at the shortest: a
narrower grid would have changed those steps."""
LEVENBERG_MARQUARDT_BROYDEN = "levenberg-marquardt-broyden"
"""Levenberg-Marquardt in batches whose Jacobian is Broyden-updated between simulated ones
(`fit_levenberg_marquardt(secant=True)`; --lm-broyden-iterations)."""
DEFAULT_LATER_LM_BATCH = 3
"""Damped steps per batch after a start's first, of the Broyden-updated batches
(--lm-broyden-batch): one decade either way of the damping that served, the narrowest grid
around it; the first batch, with no damping known yet, has --lm-batch."""
MAX_LM_BATCH = 20
"""The most damped steps a batch may try (--lm-batch, --lm-broyden-batch), a cap: a batch that
does not improve moves the grid about its width in decades up, and a wide grid's few such moves
would overflow a float (10^308); twenty decades span far more dampings than change a step."""
VANISHED_STEP = 1e-12
"""The length (largest axis, unit coordinates) at or below which every damped step of a grid
ends a Levenberg-Marquardt start before its batch is run: at a stationary point, or with a zero
Jacobian, the batch would only simulate the current point again."""
POLISH = "CMA-ES + least-squares"
"""Least squares from CMA-ES's best point (`--polish-evaluations`): its costs include CMA-ES's."""
GRADIENT_OPTIMISERS = ("L-BFGS-B", LEAST_SQUARES, BROYDEN, LEVENBERG_MARQUARDT,
                       LEVENBERG_MARQUARDT_BROYDEN, POLISH)
"""Optimisers whose evaluations are runs with sensitivities."""
QUICK_GAITS, QUICK_TRAIN, QUICK_VALIDATE = "A1+A2", "1:1", "2:2"
RESULT_COLUMNS = ["parameter_set", "n_parameters", "optimiser", "starts", "evaluations",
                  "robot_seconds", "robot_seconds_cost_equivalent", "wall_s", "objective",
                  "validate_objective", "robot_seconds_to_cma_objective",
                  "share_of_cma_robot_seconds", "cost_equivalent_to_cma_objective",
                  "share_of_cma_cost_equivalent", "objective_at_cma_cost", "gradient_cost_ratio",
                  "stop_reasons"]
CMA_BUDGET_COLUMNS = ["parameter_set", "cma_generations", "cma_robot_seconds", "cma_objective",
                      "optimiser", "cost_equivalent_to_cma_objective",
                      "share_of_cma_cost_equivalent"]
"""The columns of `gradient_fit_cma_budgets.csv` (`cma_budget_shares`)."""


class Recorder:
    """Every evaluation of one optimiser: cumulative cost and best objective so far."""

    def __init__(self, parameter_set: str, optimiser: str, on_add=None):
        self.parameter_set, self.optimiser, self.on_add = parameter_set, optimiser, on_add
        self.rows: List[dict] = []
        self.started = time.perf_counter()
        self.best_objective, self.best_units = math.inf, None
        self.robot_seconds = self.cost_equivalent = 0.0
        self.stop_reasons: List[str] = []
        self.carried: List[dict] = []
        """Where a `continuing` recorder starts: one row of its predecessor's cost-equivalent
        robot-seconds and best objective (empty for a recorder of its own)."""

    @classmethod
    def continuing(cls, previous: "Recorder", optimiser: str, on_add=None) -> "Recorder":
        """A recorder for an optimiser that starts where `previous` ended (a polish of its
        best point): its robot-seconds, wall time and best point carried over, so that its rows
        give the two optimisers' cost together."""
        recorder = cls(previous.parameter_set, optimiser, on_add)
        last = previous.rows[-1]
        recorder.robot_seconds = last["robot_seconds"]
        recorder.cost_equivalent = last["robot_seconds_cost_equivalent"]
        recorder.started -= last["wall_s"]
        recorder.best_objective = previous.best_objective
        recorder.best_units = np.array(previous.best_units, dtype=float)
        recorder.carried = [{"objective": previous.best_objective,
                             "robot_seconds_cost_equivalent": recorder.cost_equivalent}]
        return recorder

    def stopped(self, start: int, reason: str):
        """Record why the optimiser's run from start `start` (a CMA-ES restart) ended: its
        library's own words (scipy's message, cma's termination conditions), or the budget's
        (`fit_lbfgs`)."""
        self.stop_reasons.append(f"start {start}: {reason}")

    def add(self, units, objective, robot_seconds, cost_equivalent, start=0):
        self.robot_seconds += robot_seconds
        self.cost_equivalent += cost_equivalent
        if objective < self.best_objective:
            self.best_objective, self.best_units = objective, np.array(units, dtype=float)
        self.rows.append({"parameter_set": self.parameter_set, "optimiser": self.optimiser,
                          "start": start, "evaluation": len(self.rows) + 1,
                          "objective": objective, "best_objective": self.best_objective,
                          "robot_seconds": self.robot_seconds,
                          "robot_seconds_cost_equivalent": self.cost_equivalent,
                          "wall_s": time.perf_counter() - self.started})
        if self.on_add is not None:
            self.on_add()


class Problem:
    """The objective on one box: simulations of every gait at a point, its value and
    gradient in unit coordinates."""

    def __init__(self, box, base, gaits, trials, train, solver, arch):
        self.box, self.base, self.gaits, self.trials = box, base, list(gaits), trials
        self.train, self.solver, self.arch = train, solver, arch
        self.record = nearest_interval(identify.RECORD_INTERVAL_S, solver.dt)
        self.window_s = train[1] * base.period
        self.names = [spec.sensitivity_name for spec in box]
        idle = set(identify.unfired_axes(box, self.gaits))
        self.moved = np.array([spec.label not in idle for spec in box])
        """(D,) whether any gait moves the axis: the per-actuator axes of actuators no gait
        fires have derivatives exactly zero, so a run with sensitivities leaves them out
        (`moved_names`) and their Jacobian columns are zeros."""
        self.moved_names = [name for name, moved in zip(self.names, self.moved) if moved]

    def embedded(self, moved_units, around) -> np.ndarray:
        """A point of the whole box (D,) in unit coordinates: the moved axes' units (the
        gradient fits search those alone), the others as in `around` (D,)."""
        units = np.array(around, dtype=float)
        units[self.moved] = moved_units
        return units

    def moved_columns(self, jacobian) -> np.ndarray:
        """The moved axes' columns (R, D_moved) of a Jacobian (R, D), row-major as the whole:
        a boolean column index gives them column-major, and scipy's trust-region steps on
        the same numbers in the other layout differ in the last bits (its products sum in
        another order), which the fits' ill-conditioned steps (condition numbers ~1e9) carry
        into visibly other paths (an audit, 2026-12: on "20fired", where every axis moves,
        the secant fit's sixth point 845.3 against 839.3 and its end 841.9 against 808.2)."""
        return np.ascontiguousarray(jacobian[:, self.moved])

    def params(self, units) -> list:
        return identify.box_params(self.box, identify.box_values(self.box, units), self.base,
                                   self.gaits)

    def runs(self, params, cycles, sensitivities=()):
        result = simulate(params, cycles * self.base.period, self.solver, arch=self.arch,
                          record_interval_s=self.record, sensitivities=sensitivities,
                          progress=False)
        return identification.result_runs(result, params), result

    def residuals(self, units) -> np.ndarray:
        """Residuals (R,) of `fit_terms` from a run without sensitivities (an instance's rows
        are bitwise those of the run with them); for a failed simulation R residuals of inf (a
        trial point scipy's trust region shrinks away from, its objective inf as CMA-ES's
        failed points: the finite penalty of `fit_terms` was accepted as a step from a point
        scoring above it, an audit, 2026-12)."""
        units = np.clip(np.asarray(units, dtype=float), 0.0, 1.0)
        return self.scored_points(units[None, :])[1][0]

    def scored_points(self, unit_points):
        """(objectives (P,), residuals (P, R)) of points (P, D) on the training window from one
        batched run without sensitivities: each point's objective as `objectives` gives it (the
        same per-gait fits) and its residuals as `residuals` does; inf, and a row of inf, where
        a simulation failed."""
        unit_points = np.atleast_2d(unit_points)
        runs, _ = self.runs(self.params(unit_points), self.train[1])
        count = identification.residual_count(len(self.gaits), self.train)
        objectives = np.full(len(unit_points), math.inf)
        residuals = np.full((len(unit_points), count), math.inf)
        for p in range(len(unit_points)):
            part = runs[p * len(self.gaits):(p + 1) * len(self.gaits)]
            if any(run is None for run in part):
                continue
            # the residuals need no derivatives: one zero column stands in for them
            no_derivatives = {gait: np.zeros((len(run.path.t_s), 2, 1))
                              for gait, run in zip(self.gaits, part)}
            residuals[p], _, table = identification.objective_residuals(
                dict(zip(self.gaits, part)), no_derivatives, self.trials, self.train)
            objectives[p] = identification.objective_of(table)
        return objectives, residuals

    def failed_residuals(self) -> np.ndarray:
        """R equal residuals whose squares sum to `identify.FAILED_PENALTY`."""
        count = identification.residual_count(len(self.gaits), self.train)
        return np.full(count, math.sqrt(identify.FAILED_PENALTY / count))

    def fit_terms(self, units):
        """The objective as a sum of squares at a point, from one run with sensitivities:
        residuals (R,), their Jacobian (R, D) at the fitted phases held
        (`identification.objective_residuals`) and the gradient's part from the phases moving
        with the point (D,; `identification.phase_motion`, zero on a one-cycle window), both in
        unit coordinates; for a failed simulation R equal residuals whose squares sum to
        `identify.FAILED_PENALTY`, and zero derivatives."""
        units = np.clip(np.asarray(units, dtype=float), 0.0, 1.0)
        runs, result = self.runs(self.params(units[None, :]), self.train[1], self.moved_names)
        if any(run is None for run in runs):
            failed = self.failed_residuals()
            return failed, np.zeros((len(failed), len(self.box))), np.zeros(len(self.box))
        derivatives = {gait: identification.record_derivatives(
            result.trajectory_sensitivities, b, self.moved_names)
            for b, gait in enumerate(self.gaits)}
        simulated = dict(zip(self.gaits, runs))
        residuals, moved_jacobian, table = identification.objective_residuals(
            simulated, derivatives, self.trials, self.train)
        moved_motion = identification.phase_motion(simulated, derivatives, self.trials, table,
                                                   self.train)
        jacobian = np.zeros((len(residuals), len(self.box)))
        jacobian[:, self.moved] = moved_jacobian
        motion = np.zeros(len(self.box))
        motion[self.moved] = moved_motion
        per_unit = identify.box_value_per_unit(
            self.box, identify.box_values(self.box, units[None, :])[0])
        return residuals, jacobian * per_unit, motion * per_unit

    def residuals_and_jacobian(self, units):
        """Residuals (R,) and their Jacobian (R, D) of `fit_terms` (the least-squares fit's)."""
        residuals, jacobian, _ = self.fit_terms(units)
        return residuals, jacobian

    def value_and_gradient(self, units):
        """(objective, gradient (D,) in unit coordinates): Σ r² and 2·Jᵀr plus the phases'
        motion, of `fit_terms` (the gradient of the objective with the phases re-fitted)."""
        residuals, jacobian, motion = self.fit_terms(units)
        return float(residuals @ residuals), 2.0 * jacobian.T @ residuals + motion

    def uncertainty(self, units) -> pd.DataFrame:
        """`identification.parameter_uncertainty` at a point (unit coordinates): its residuals
        and their Jacobian with respect to the parameters' values, from one run with the
        sensitivities."""
        units = np.clip(np.asarray(units, dtype=float), 0.0, 1.0)
        values = identify.box_values(self.box, units[None, :])[0]
        residuals, jacobian, _ = self.fit_terms(units)
        # labelled as the box's axes (NAME[INDEX] from 1), like the study's other tables
        per_unit = identify.box_value_per_unit(self.box, values)
        return identification.parameter_uncertainty(residuals, jacobian / per_unit,
                                                    [spec.label for spec in self.box], values)

    def gait_tables(self, unit_points) -> list:
        """Per point (P, D): `identification.trajectory_objective`'s per-gait table on the
        training window (each gait's phase fitted), None where a simulation failed; one batched
        run."""
        unit_points = np.atleast_2d(unit_points)
        runs, _ = self.runs(self.params(unit_points), self.train[1])
        tables = []
        for p in range(len(unit_points)):
            part = runs[p * len(self.gaits):(p + 1) * len(self.gaits)]
            tables.append(None if any(r is None for r in part) else
                          identification.trajectory_objective(dict(zip(self.gaits, part)),
                                                              self.trials, self.train))
        return tables

    def objectives(self, unit_points) -> np.ndarray:
        """The objective of every point (P, D) on the training window, one batched run."""
        return np.array([math.inf if table is None else identification.objective_of(table)
                         for table in self.gait_tables(unit_points)])

    def validate(self, units, validate) -> float:
        """The objective on the validation window with the phases fitted on training."""
        runs, _ = self.runs(self.params(np.atleast_2d(units)), validate[1])
        if any(run is None for run in runs):
            return math.inf
        simulated = dict(zip(self.gaits, runs))
        phases = dict(zip(self.gaits, identification.trajectory_objective(
            simulated, self.trials, self.train)["phase_s"]))
        return identification.objective_of(identification.trajectory_objective(
            simulated, self.trials, validate, phases=phases))


def measure_cost_ratio(problem: Problem, repeats: int = COST_REPEATS) -> float:
    """What one L-BFGS-B call costs in runs: the wall time of the simulation of
    `Problem.value_and_gradient` (every gait with the box's sensitivities) over that of the same
    simulation without them, at the base point. Each is run once first (compilation, not
    counted), then `repeats` times interleaved; the ratio of the fastest of each (the least
    disturbed by the rest of the machine; `profiling.interleaved_rounds`)."""
    params = problem.params(identify.start_units(problem.box, problem.base)[None, :])
    window = problem.train[1] * problem.base.period
    calls = {"plain": lambda: simulate(params, window, problem.solver, arch=problem.arch,
                                       record_interval_s=problem.record, progress=False),
             "gradient": lambda: simulate(params, window, problem.solver, arch=problem.arch,
                                          record_interval_s=problem.record, progress=False,
                                          sensitivities=problem.moved_names)}
    _, times, _ = interleaved_rounds(list(calls.values()), repeats)
    best = dict(zip(calls, times.min(axis=0)))
    return float(best["gradient"] / best["plain"])


def start_points(problem: Problem, starts: int, seed: int):
    """The gradient fits' starts in unit coordinates: the base model, then uniform random
    points (seeded)."""
    rng = np.random.default_rng(seed)
    for start in range(starts):
        yield (identify.start_units(problem.box, problem.base) if start == 0
               else rng.uniform(0.0, 1.0, len(problem.box)))


def record_gradient_call(recorder: Recorder, problem: Problem, units, value: float,
                         cost_ratio: float, start: int):
    """Add one simulation with the box's sensitivities to `recorder`: (1 + 2·D) instances per
    gait with the replicas counted (D the axes a gait moves, `Problem.moved_names`),
    `cost_ratio` runs cost-equivalent."""
    per_evaluation = problem.window_s * len(problem.gaits)
    recorder.add(units, value, per_evaluation * (1 + REPLICAS_PER_DIRECTION
                                                 * len(problem.moved_names)),
                 per_evaluation * cost_ratio, start)


def record_plain_call(recorder: Recorder, problem: Problem, units, value: float, start: int):
    """Add one simulation without sensitivities to `recorder`: one run of every gait."""
    per_evaluation = problem.window_s * len(problem.gaits)
    recorder.add(units, value, per_evaluation, per_evaluation, start)


def fit_lbfgs(problem: Problem, starts: int, max_evaluations: int, seed: int,
              recorder: Recorder, cost_ratio: float) -> Recorder:
    """Multi-start L-BFGS-B over the unit box (module docstring), every evaluation into
    `recorder`, a call counted as `cost_ratio` runs in the cost-equivalent robot-seconds. It
    searches the axes a fitted gait moves (`Problem.moved`), the others held at the start's.
    A start stops after `max_evaluations` evaluations at most (`optimise.minimise_lbfgsb`:
    scipy's own cap let a line search run past it, a cap of 6 made 9 calls)."""
    parameter_set = recorder.parameter_set
    for start, x0 in enumerate(start_points(problem, starts, seed)):

        def fun(moved_units, start=start, x0=x0):
            units = problem.embedded(moved_units, x0)
            value, gradient = problem.value_and_gradient(units)
            record_gradient_call(recorder, problem, units, value, cost_ratio, start)
            print(f"set {parameter_set} L-BFGS-B start {start}: objective {value:.5g}, "
                  f"|gradient| {np.linalg.norm(gradient):.3g}", flush=True)
            return value, gradient[problem.moved]

        result = minimise_lbfgsb(fun, x0[problem.moved], [(0.0, 1.0)] * int(problem.moved.sum()),
                                 max_evaluations, max_evaluations, budget="--lbfgs-evaluations")
        recorder.stopped(start, str(result.message))
    return recorder


def broyden_update(jacobian: np.ndarray, step: np.ndarray,
                   residual_change: np.ndarray) -> np.ndarray:
    """Broyden's rank-one update of a Jacobian (R, D) after a step (D,) that changed the
    residuals by `residual_change` (R,): the least change (in the Frobenius norm) that makes the
    Jacobian map the step to the change (the secant condition); in directions orthogonal to the
    step it maps as before."""
    step = np.asarray(step, dtype=float)
    mismatch = np.asarray(residual_change, dtype=float) - jacobian @ step
    return jacobian + np.outer(mismatch, step) / float(step @ step)


def step_agreement(residuals_before: np.ndarray, residuals_after: np.ndarray,
                   jacobian: np.ndarray, step: np.ndarray) -> float:
    """The reduction of Σ r² a step achieved over the reduction the linear model r + J·s
    predicted (trust-region methods' ρ); 0 where the model predicted none."""
    before = float(residuals_before @ residuals_before)
    predicted = before - float(np.sum((residuals_before + jacobian @ step) ** 2))
    achieved = before - float(residuals_after @ residuals_after)
    return achieved / predicted if predicted > 0.0 else 0.0


def secant_jacobian(last_units, last_residuals, last_jacobian, refused: bool, units,
                    residuals) -> Optional[np.ndarray]:
    """The secant fit's Jacobian at an accepted point `units` (D,) with `residuals` (R,), from
    the last Jacobian (R, D), simulated or updated, at `last_units` with `last_residuals`: its
    Broyden update with the step between them (`broyden_update`), or None, to simulate it, where
    the last one served badly: a trial point since scored no better than its point (`refused`)
    or the step achieved less than SECANT_AGREEMENT of the reduction it predicted
    (`step_agreement`; at the threshold itself the update is taken)."""
    if refused:
        return None
    step = np.asarray(units, dtype=float) - last_units
    if step_agreement(last_residuals, residuals, last_jacobian, step) < SECANT_AGREEMENT:
        return None
    return broyden_update(last_jacobian, step, residuals - last_residuals)


class SecantState:
    """The secant fit's last Jacobian (simulated or updated) at scipy's current point, and
    whether a trial point since has scored no better than that point (`fit_least_squares`)."""

    def __init__(self, units, residuals, jacobian):
        self.moved_to(units, residuals, jacobian)

    def moved_to(self, units, residuals, jacobian):
        """scipy accepted `units` (its residuals, the Jacobian it gets there)."""
        self.units, self.residuals = np.array(units, dtype=float), residuals
        self.jacobian, self.refused = jacobian, False

    def tried(self, residuals):
        """A trial point's residuals: one scoring no better than the current point's (a step
        scipy refuses: its objective not below) marks the Jacobian as having served badly."""
        if residuals @ residuals >= self.residuals @ self.residuals:
            self.refused = True

    def jacobian_at(self, units, residuals) -> Optional[np.ndarray]:
        """The Jacobian at the accepted point `units`: `secant_jacobian` from this state."""
        return secant_jacobian(self.units, self.residuals, self.jacobian, self.refused, units,
                               residuals)


def fit_least_squares(problem: Problem, points, max_evaluations: int, recorder: Recorder,
                      cost_ratio: float, method: str = DEFAULT_LEAST_SQUARES_METHOD,
                      secant: bool = False) -> Recorder:
    """Multi-start trust-region least squares over the unit box (scipy's `least_squares`,
    `method` one of LEAST_SQUARES_METHODS: Gauss-Newton steps on the residuals' Jacobian within
    a trust region that the bounds [0, 1] of each axis limit; axes scaled by the Jacobian's
    columns), from each of `points` (unit coordinates: `start_points`, as `fit_lbfgs`, or
    another optimiser's best point to polish), `max_evaluations` residual evaluations per
    start. A start's first point costs one run with sensitivities (`cost_ratio` runs: its
    residuals and the Jacobian scipy's first step needs; one run without them when the budget
    is one point, which no step follows). Every later trial point costs one run without
    sensitivities (its residuals); the run with sensitivities (the Jacobian) is made only where
    scipy asks for it, at the points it accepts and not at the last one a start's budget allows
    (no step follows it): a rejected trial point, and the last, cost one run, an accepted one
    1 + `cost_ratio` (at 1595fb0 and before, every point got the Jacobian with its residuals;
    before cb4f234 the first point's residuals were a run of their own too). Every
    simulation goes into `recorder` (a Jacobian's row with its point's objective). Why trf by
    default: `LEAST_SQUARES_METHODS`.

    The fit searches the axes a fitted gait moves (`Problem.moved`; the others held at the
    start's values: their columns are zero, and trf's steps wandered along them, an audit,
    2026-12). A trial point whose run fails scores inf (`Problem.residuals`): scipy shrinks
    its trust region and tries again; a start whose run fails gets `Problem.failed_residuals`
    (scipy needs a finite start).

    With `secant`, the Jacobian scipy asks for at an accepted point is simulated only where the
    last one served badly: where a trial point since the last Jacobian (simulated or updated,
    at scipy's current point) scored no better than that point (a step was refused), or the
    step to this point achieved less than SECANT_AGREEMENT of the reduction its linear model
    predicted. Elsewhere
    it is the last Jacobian updated by Broyden's rule (`broyden_update`) with the step and the
    change of the residuals the trial point's own run gave, no simulation. (The residuals'
    actual change includes the phases' re-fit, which the simulated Jacobian, at the phases
    held, does not.)"""
    from scipy.optimize import least_squares
    parameter_set = recorder.parameter_set
    for start, x0 in enumerate(points):
        x0 = np.asarray(x0, dtype=float)
        trial_points = []
        spent = []
        start_jacobian = {}
        state = []  # the secant fit's SecantState, from the start's Jacobian on

        def residuals(moved_units, start=start, x0=x0):
            units = problem.embedded(moved_units, x0)
            if not trial_points and max_evaluations > 1:
                # scipy's first step needs the start's Jacobian: one run gives both
                values, derivatives = problem.residuals_and_jacobian(units)
                start_jacobian[moved_units.tobytes()] = problem.moved_columns(derivatives)
                record_gradient_call(recorder, problem, units, float(values @ values),
                                     cost_ratio, start)
                state.append(SecantState(moved_units, values,
                                         start_jacobian[moved_units.tobytes()]))
            else:
                values = problem.residuals(units)
                if not trial_points and not np.all(np.isfinite(values)):
                    values = problem.failed_residuals()  # scipy needs a finite start
                record_plain_call(recorder, problem, units, float(values @ values), start)
                if state:
                    state[0].tried(values)
            value = float(values @ values)
            trial_points.append((np.array(moved_units), values))
            print(f"set {parameter_set} {recorder.optimiser} start {start}: objective "
                  f"{value:.5g}", flush=True)
            return values

        def jacobian(moved_units, start=start, x0=x0):
            if moved_units.tobytes() in start_jacobian:
                return start_jacobian.pop(moved_units.tobytes())
            if len(trial_points) == max_evaluations:
                # the budget is spent: scipy asks only to test convergence before it stops, and
                # no step will use this Jacobian, so none is simulated (zeros end the fit)
                spent.append(True)
                return np.zeros((len(trial_points[-1][1]), len(moved_units)))
            point, values = trial_points[-1]
            # scipy asks at the trial point it has just had; anywhere else, simulate
            derivatives = (state[0].jacobian_at(point, values)
                           if secant and np.array_equal(point, moved_units) else None)
            if derivatives is None:
                units = problem.embedded(moved_units, x0)
                values, derivatives = problem.residuals_and_jacobian(units)
                derivatives = problem.moved_columns(derivatives)
                record_gradient_call(recorder, problem, units, float(values @ values),
                                     cost_ratio, start)
            state[0].moved_to(moved_units, values, derivatives)
            return derivatives

        result = least_squares(residuals, x0[problem.moved], jac=jacobian, bounds=(0.0, 1.0),
                               method=method, x_scale="jac", max_nfev=max_evaluations)
        # the zeros that end a spent budget read to scipy as a zero gradient: say what it was
        recorder.stopped(start, f"its {max_evaluations} trial points were spent" if spent
                         else str(result.message))
    return recorder


def damping_grid(centre: float, batch: int) -> np.ndarray:
    """`batch` dampings a decade apart around `centre`: centre · 10^k, k from -(batch // 2)
    up, ascending (the longest step first)."""
    return centre * 10.0 ** (np.arange(batch) - batch // 2)


def damped_steps(residuals: np.ndarray, jacobian: np.ndarray, units: np.ndarray,
                 dampings: Sequence[float]) -> np.ndarray:
    """Levenberg-Marquardt's trial points (K, D) from `units` (D,) in the unit box, one per
    damping λ: the step s minimising |r + J·s|² + λ·|diag(d)·s|² within the box (0 ≤ units +
    s ≤ 1, scipy's bounded-variable least squares on the stacked system), d the Jacobian's
    column norms (Marquardt's scaling: λ relative to each axis's curvature; an axis whose
    column is zero, which the residuals do not see, is left where it is: bvls starts from the
    minimum-norm least-squares solution, zero along it, and no gradient moves it). λ → 0 gives
    the box-constrained Gauss-Newton step, a large λ a short step down the scaled gradient.
    `residuals` (R,), `jacobian` (R, D)."""
    from scipy.optimize import lsq_linear
    units = np.asarray(units, dtype=float)
    scale = np.linalg.norm(jacobian, axis=0)
    stacked_residuals = np.concatenate([-np.asarray(residuals, dtype=float),
                                        np.zeros(len(units))])
    points = []
    for damping in dampings:
        stacked = np.vstack([jacobian, math.sqrt(damping) * np.diag(scale)])
        step = lsq_linear(stacked, stacked_residuals, bounds=(-units, 1.0 - units),
                          method="bvls").x
        points.append(np.clip(units + step, 0.0, 1.0))  # bvls ends on a bound to round-off
    return np.array(points)


def record_batch(recorder: Recorder, problem: Problem, unit_points, objectives, start: int):
    """Add one batched run without sensitivities of P points (P, D) to `recorder`: one row per
    point, the whole batch's cost (P runs of every gait) on its first, since no point's
    objective is known before the batch has run."""
    per_batch = problem.window_s * len(problem.gaits) * len(unit_points)
    for k, (units, value) in enumerate(zip(unit_points, objectives)):
        cost = per_batch if k == 0 else 0.0
        recorder.add(units, float(value), cost, cost, start)


def fit_levenberg_marquardt(problem: Problem, points, iterations: int, batch: int,
                            recorder: Recorder, cost_ratio: float, secant: bool = False,
                            later_batch: Optional[int] = None) -> Recorder:
    """Multi-start Levenberg-Marquardt over the unit box whose every Jacobian is tried with
    `batch` dampings at once: from each of `points` (unit coordinates, `start_points`), one
    run with sensitivities (residuals and Jacobian, `cost_ratio` runs), then `iterations`
    times one batched run without them of the `damped_steps` at the `damping_grid` around the
    last damping that served (MARQUARDT_DAMPING at first), scored by the trajectory objective
    as CMA-ES's points are (`Problem.objectives`; failed runs score inf). The best point of a
    batch that scores below the current point becomes the current one, the grid centred on
    its damping, and the Jacobian is simulated there if another batch follows; a batch with
    none below moves the grid up (shorter steps from the same Jacobian, no simulation), the
    next grid's least damping a decade above this one's largest (`batch` decades up). A start
    ends when its batches are spent, or before a batch whose every step is at most
    VANISHED_STEP long. A trust-region method tries one step length per run; the
    batch simulator runs a grid of them in one call, at the robot-seconds of each
    (`record_batch`). It searches the axes a fitted gait moves (`Problem.moved`), the others
    held at the start's.

    With `secant` (optimiser LEVENBERG_MARQUARDT_BROYDEN) a batch scores its points' residuals
    too (`Problem.scored_points`, the same run), and at the point it moves to the Jacobian is
    Broyden's update of the last one along the step (`secant_jacobian`), simulated only where
    that one served badly (the step achieved less than SECANT_AGREEMENT of the reduction it
    predicted); a batch with no better point from an updated Jacobian simulates the Jacobian
    at the current point and tries the same grid again, one from a simulated Jacobian moves
    the grid up, and vanishing steps from an updated Jacobian are checked with the simulated
    one before the start ends. Every batch after a start's first has `later_batch` points
    (default `batch`): the first grid brackets an unknown damping, the later ones follow the
    one that served."""
    parameter_set = recorder.parameter_set
    later_batch = batch if later_batch is None else later_batch
    for start, x0 in enumerate(points):
        units = np.asarray(x0, dtype=float)
        residuals, jacobian = problem.residuals_and_jacobian(units)
        value = float(residuals @ residuals)
        record_gradient_call(recorder, problem, units, value, cost_ratio, start)
        centre, reason = MARQUARDT_DAMPING, f"its {iterations} batches were spent"
        simulated = True  # the Jacobian is the one simulated at `units`, not an update
        for iteration in range(iterations):
            size = batch if iteration == 0 else later_batch
            dampings = damping_grid(centre, size)
            moved_points = damped_steps(residuals, problem.moved_columns(jacobian),
                                        units[problem.moved], dampings)
            if np.max(np.abs(moved_points - units[problem.moved])) <= VANISHED_STEP \
                    and not simulated:  # an updated Jacobian's stationary point: check it
                residuals, jacobian = problem.residuals_and_jacobian(units)
                record_gradient_call(recorder, problem, units, value, cost_ratio, start)
                simulated = True
                moved_points = damped_steps(residuals, problem.moved_columns(jacobian),
                                            units[problem.moved], dampings)
            if np.max(np.abs(moved_points - units[problem.moved])) <= VANISHED_STEP:
                reason = (f"its damped steps vanished (at most {VANISHED_STEP:g}) after "
                          f"{iteration} batches")
                break
            trials = np.array([problem.embedded(point, units) for point in moved_points])
            if secant:
                objectives, trial_residuals = problem.scored_points(trials)
            else:
                objectives = problem.objectives(trials)
            record_batch(recorder, problem, trials, objectives, start)
            best = int(np.argmin(objectives))
            print(f"set {parameter_set} {recorder.optimiser} start {start}: batch "
                  f"{iteration + 1}, best {objectives[best]:.5g} at damping "
                  f"{dampings[best]:.0e}", flush=True)
            last = iteration + 1 == iterations
            if objectives[best] >= value:
                if simulated:  # the next grid's least damping a decade above this one's most
                    centre *= 10.0 ** (size - size // 2 + later_batch // 2)
                elif not last:
                    residuals, jacobian = problem.residuals_and_jacobian(units)
                    record_gradient_call(recorder, problem, units, value, cost_ratio, start)
                    simulated = True
                continue
            updated = None if not secant else secant_jacobian(
                units, residuals, jacobian, False, trials[best], trial_residuals[best])
            units, centre = trials[best], dampings[best]
            if updated is not None:
                residuals, jacobian, simulated = trial_residuals[best], updated, False
                value = float(objectives[best])
            elif not last:
                residuals, jacobian = problem.residuals_and_jacobian(units)
                value = float(residuals @ residuals)
                record_gradient_call(recorder, problem, units, value, cost_ratio, start)
                simulated = True
        recorder.stopped(start, reason)
    return recorder


def fit_cma(problem: Problem, settings: identify.CMASettings, recorder: Recorder) -> Recorder:
    """CMA-ES from the base model over the unit box (module docstring) with `settings`
    (population, generations, seed, σ0), every evaluation into `recorder`."""
    parameter_set = recorder.parameter_set
    per_point = problem.window_s * len(problem.gaits)

    def evaluate(unit_points):
        values = problem.objectives(unit_points)
        for units, value in zip(unit_points, values):
            recorder.add(units, value, per_point, per_point)
        print(f"set {parameter_set} CMA-ES: best {recorder.best_objective:.5g}", flush=True)
        return pd.DataFrame({"objective": values})

    result = identify.minimise_cmaes(problem.box, identify.start_units(problem.box, problem.base),
                                     evaluate, settings)
    for restart, reason in enumerate(result.stop_reasons):
        recorder.stopped(restart, reason)
    return recorder


def cost_to_reach(recorder: Recorder, target: float, count: str) -> float:
    """The cumulative cost `count` (a cost column of `Recorder.rows`) at the first evaluation
    whose best objective so far is at or below `target`; NaN if none is."""
    return next((row[count] for row in recorder.rows if row["best_objective"] <= target),
                math.nan)


def cma_budget_shares(recorders: Sequence[Recorder], populations: dict) -> pd.DataFrame:
    """The goal's comparison against every CMA-ES budget up to the run's: per parameter set,
    CMA-ES generation g (its first g whole generations, `populations[set]` points each) and
    other optimiser, CMA-ES's best objective after g generations and its robot-seconds then,
    and the cost-equivalent robot-seconds the optimiser needed to reach that objective
    (`cost_to_reach`) with their share of CMA-ES's. CMA-ES's first g generations do not depend
    on how many follow, so they are a g-generation run's. The polish, whose costs include
    CMA-ES's whole run, is left out. One row per set, g and optimiser (CMA_BUDGET_COLUMNS);
    empty for sets without CMA-ES."""
    rows = []
    for cma in (r for r in recorders if r.optimiser == "CMA-ES"):
        population = populations[cma.parameter_set]
        others = [r for r in recorders if r.parameter_set == cma.parameter_set
                  and r.optimiser not in ("CMA-ES", POLISH)]
        for generation in range(1, len(cma.rows) // population + 1):
            last = cma.rows[generation * population - 1]
            target, cma_cost = last["best_objective"], last["robot_seconds"]
            for recorder in others:
                cost = cost_to_reach(recorder, target, "robot_seconds_cost_equivalent")
                rows.append({"parameter_set": cma.parameter_set, "cma_generations": generation,
                             "cma_robot_seconds": cma_cost, "cma_objective": target,
                             "optimiser": recorder.optimiser,
                             "cost_equivalent_to_cma_objective": cost,
                             "share_of_cma_cost_equivalent": cost / cma_cost})
    return pd.DataFrame(rows, columns=CMA_BUDGET_COLUMNS)


def summarise(recorders: Sequence[Recorder], problem_of, validate,
              cost_ratios: dict) -> pd.DataFrame:
    """One row per optimiser (RESULT_COLUMNS); `cost_ratios`: parameter set -> the measured
    cost of a gradient call in runs (1 for CMA-ES's points)."""
    rows = []
    for recorder in recorders:
        last = recorder.rows[-1]
        rows.append({"parameter_set": recorder.parameter_set,
                     "n_parameters": len(problem_of[recorder.parameter_set].box),
                     "optimiser": recorder.optimiser,
                     "starts": len({row["start"] for row in recorder.rows}),
                     "evaluations": len(recorder.rows), "robot_seconds": last["robot_seconds"],
                     "robot_seconds_cost_equivalent": last["robot_seconds_cost_equivalent"],
                     "wall_s": last["wall_s"], "objective": recorder.best_objective,
                     "validate_objective": problem_of[recorder.parameter_set].validate(
                         recorder.best_units, validate),
                     "gradient_cost_ratio": (cost_ratios[recorder.parameter_set]
                                             if recorder.optimiser in GRADIENT_OPTIMISERS
                                             else 1.0),
                     "stop_reasons": "; ".join(recorder.stop_reasons)})
    table = pd.DataFrame(rows)
    for parameter_set, part in table.groupby("parameter_set", sort=False):
        cma = part[part["optimiser"] == "CMA-ES"]
        if cma.empty:
            continue
        target, cma_cost = float(cma["objective"].iloc[0]), float(cma["robot_seconds"].iloc[0])
        for recorder in recorders:
            if recorder.parameter_set != parameter_set:
                continue
            index = table.index[(table["parameter_set"] == parameter_set)
                                & (table["optimiser"] == recorder.optimiser)]
            for count, cost_column, share_column in (
                    ("robot_seconds", "robot_seconds_to_cma_objective",
                     "share_of_cma_robot_seconds"),
                    ("robot_seconds_cost_equivalent", "cost_equivalent_to_cma_objective",
                     "share_of_cma_cost_equivalent")):
                cost = cost_to_reach(recorder, target, count)
                table.loc[index, cost_column] = cost
                table.loc[index, share_column] = cost / cma_cost
            # the same budget for every optimiser: what each had reached once it had spent
            # CMA-ES's whole run, a call counted at its measured cost (NaN: its first call
            # alone cost more; a polish starts with CMA-ES's best at CMA-ES's cost)
            within = [row["objective"] for row in recorder.carried + recorder.rows
                      if row["robot_seconds_cost_equivalent"] <= cma_cost]
            table.loc[index, "objective_at_cma_cost"] = min(within) if within else math.nan
    return table.reindex(columns=RESULT_COLUMNS)


def held_out_scores(held_out: Problem, recorders: Sequence[Recorder]) -> pd.DataFrame:
    """The start and every recorder's best point (one set's; `held_out` is that set's box on
    the held-out gaits) scored on the held-out gaits in one batched run: one row per point
    and gait, columns parameter_set, point ("start" or the optimiser), then
    `identification.TRIAL_COLUMNS` (objective inf and the rest NaN where the point's
    simulation failed)."""
    points = [("start", identify.start_units(held_out.box, held_out.base))] + [
        (recorder.optimiser, recorder.best_units) for recorder in recorders]
    tables = held_out.gait_tables(np.array([units for _, units in points]))
    parameter_set = recorders[0].parameter_set
    rows = []
    for (point, _), table in zip(points, tables):
        if table is None:
            table = pd.DataFrame({"gait": held_out.gaits, "objective": math.inf},
                                 columns=identification.TRIAL_COLUMNS)
        rows.append(table.assign(parameter_set=parameter_set, point=point))
    return pd.concat(rows, ignore_index=True)[["parameter_set", "point",
                                               *identification.TRIAL_COLUMNS]]


SEGMENT_FRACTIONS = np.linspace(0.0, 1.0, 11)
"""Where `segment_scores` scores each segment: fractions of the way from an optimiser's best
point (0) to the best point of its set (1)."""


def segment_scores(problem: Problem, recorders: Sequence[Recorder],
                   fractions=SEGMENT_FRACTIONS) -> pd.DataFrame:
    """The objective along the straight segment, in unit coordinates, from each recorder's
    best point to the lowest of them (one set's recorders; `problem` is its box), at
    `fractions` of the way, in one batched run: whether the optimisers that stopped higher
    stopped in another valley (the objective rises on the way, at least along this line) or
    short of the same one (it falls all the way). One row per segment and fraction, columns
    parameter_set, optimiser (the segment's start), best_optimiser (its end), fraction,
    objective, then `objective_<gait>` per fitted gait (the gait's objective, its phase
    fitted at that point); objective inf and the gaits' NaN where a simulation failed. A
    recorder with no finite point, or whose best point is the best one, has no segment (an
    empty table when no recorder has one); a point on two segments is simulated once."""
    scored = [r for r in recorders if r.best_units is not None]
    if not scored:
        return pd.DataFrame()
    best = min(scored, key=lambda r: r.best_objective)
    segments = [r for r in scored if not np.array_equal(r.best_units, best.best_units)]
    # (1 − f)·a + f·b: each end is its point exactly
    points = [(1.0 - fraction) * r.best_units + fraction * best.best_units
              for r in segments for fraction in fractions]
    # each distinct point simulated once (a polish that kept CMA-ES's point, two fits ending
    # at one point: an audit, 2026-12)
    distinct = {point.tobytes(): point for point in points}
    scored_tables = dict(zip(distinct, problem.gait_tables(np.array(list(distinct.values())))
                             if distinct else []))
    tables = [scored_tables[point.tobytes()] for point in points]
    rows = []
    for index, table in enumerate(tables):
        recorder = segments[index // len(fractions)]
        row = {"parameter_set": recorder.parameter_set, "optimiser": recorder.optimiser,
               "best_optimiser": best.optimiser, "fraction": fractions[index % len(fractions)],
               "objective": (math.inf if table is None
                             else identification.objective_of(table))}
        gaits = (dict(zip(table["gait"], table["objective"])) if table is not None else {})
        row.update({f"objective_{gait}": gaits.get(gait, math.nan) for gait in problem.gaits})
        rows.append(row)
    return pd.DataFrame(rows)


def save_titled(fig, csv_path, png_path) -> Path:
    """Save a figure drawn from `csv_path` (dpi 120), titled with the run settings its
    provenance sidecar records (`cli.run_settings`; none without a sidecar)."""
    settings = cli.run_settings(csv_path)
    if settings:
        fig.suptitle(settings, fontsize=8)
    return cli.save_figure(fig, png_path, dpi=120)


def plot_segments(csv_path, png_path) -> Path:
    """From gradient_fit_segments.csv: one row of panels per parameter set, one panel per
    segment (an optimiser's best point to its set's best), the objective (black) and each
    gait's against the fraction of the way, on a log scale."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path, dtype={"parameter_set": str})
    sets = list(dict.fromkeys(table["parameter_set"]))
    width = max(table.groupby("parameter_set")["optimiser"].nunique())
    fig, axes = plt.subplots(len(sets), width, figsize=(4.6 * width, 3.6 * len(sets)),
                             squeeze=False)
    gait_columns = [c for c in table.columns if c.startswith("objective_")]
    for row, parameter_set in enumerate(sets):
        part = table[table["parameter_set"] == parameter_set]
        segments = list(dict.fromkeys(part["optimiser"]))
        for column in range(width):
            ax = axes[row, column]
            if column >= len(segments):
                ax.set_visible(False)
                continue
            segment = part[part["optimiser"] == segments[column]]
            for gait_column in gait_columns:
                ax.plot(segment["fraction"], segment[gait_column], lw=1.0,
                        label=gait_column.removeprefix("objective_"))
            ax.plot(segment["fraction"], segment["objective"], color="black", lw=2.0,
                    label="objective (mean)")
            ax.set_yscale("log")
            ax.set_xlabel(f"fraction of the way to {segment['best_optimiser'].iloc[0]}'s "
                          "point")
            ax.set_ylabel("trajectory objective")
            ax.set_title(f"{parameter_set} parameters: from {segments[column]}'s point",
                         fontsize=9)
            ax.legend(fontsize=7)
    return save_titled(fig, csv_path, png_path)


def plot_history(csv_path, png_path) -> Path:
    """Best objective so far against robot-seconds, one column of panels per parameter set, one
    line per optimiser (from gradient_fit_history.csv): above with every replica counted as an
    instance, below with a gradient call counted at its measured cost (cost-equivalent)."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path, dtype={"parameter_set": str})
    sets = list(dict.fromkeys(table["parameter_set"]))
    fig, axes = plt.subplots(2, len(sets), figsize=(5.2 * len(sets), 8.0), squeeze=False)
    counts = (("robot_seconds", "robot-seconds, replicas counted as instances"),
              ("robot_seconds_cost_equivalent", "robot-seconds, a call at its measured cost"))
    for column, parameter_set in enumerate(sets):
        part = table[table["parameter_set"] == parameter_set]
        for (count, label), ax in zip(counts, axes[:, column]):
            for optimiser, rows in part.groupby("optimiser"):
                ax.step(rows[count], rows["best_objective"], where="post", label=optimiser)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(label)
            ax.set_ylabel("best trajectory objective so far")
            ax.set_title(f"{parameter_set} parameters", fontsize=9)
            ax.legend(fontsize=8)
    return save_titled(fig, csv_path, png_path)


def plot_cma_budgets(csv_path, png_path) -> Path:
    """The share of CMA-ES's robot-seconds (cost-equivalent) each optimiser needed to reach
    CMA-ES's best after g generations, against g, one panel per parameter set, one line per
    optimiser (from gradient_fit_cma_budgets.csv; a budget whose objective it never reached
    leaves a gap), with the one-fifth share marked."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path, dtype={"parameter_set": str})
    sets = list(dict.fromkeys(table["parameter_set"]))
    fig, axes = plt.subplots(1, len(sets), figsize=(5.2 * len(sets), 4.2), squeeze=False)
    for parameter_set, ax in zip(sets, axes[0]):
        part = table[table["parameter_set"] == parameter_set]
        for optimiser, rows in part.groupby("optimiser", sort=False):
            ax.plot(rows["cma_generations"], rows["share_of_cma_cost_equivalent"], marker=".",
                    label=optimiser)
        ax.axhline(0.2, color="0.5", linestyle="--", linewidth=0.8, label="one fifth")
        ax.set_yscale("log")
        ax.set_xlabel("CMA-ES's generations")
        ax.set_ylabel("share of CMA-ES's robot-seconds to reach its best")
        ax.set_title(f"{parameter_set} parameters", fontsize=9)
        ax.legend(fontsize=8)
    return save_titled(fig, csv_path, png_path)


def build_parser():
    parser = cli.StudyParser("gradient_fit", DESCRIPTION)
    # the default gaits (all five measured) move every parameter of these two sets; set "20"
    # holds gains that no measured gait fires
    parser.add_argument("--sets", default=DEFAULT_SETS, quick="6",
                        help=f"parameter sets to fit, comma list of {', '.join(PARAMETER_SETS)}")
    parser.add_argument("--gaits", default="paper", quick=QUICK_GAITS,
                        help="measured gaits to fit: paper (all five) or a comma list")
    parser.add_argument("--train-cycles", default="1:3", quick=QUICK_TRAIN,
                        help="the fit window FIRST:LAST (cycles from 1)")
    parser.add_argument("--validate-cycles", default="4:6", quick=QUICK_VALIDATE,
                        help="the validation window FIRST:LAST")
    parser.add_argument("--starts", type=int, default=2, quick=1,
                        help="starts of every gradient fit (L-BFGS-B, least squares, the "
                             "batches): the base model, then random points")
    parser.add_argument("--lbfgs-evaluations", type=int, default=8, quick=2,
                        help="evaluations (objective + gradient) per L-BFGS-B start")
    parser.add_argument("--least-squares-evaluations", type=int, default=8, quick=2,
                        help="trial points (residuals; the Jacobian where accepted) per "
                             "least-squares start; 0 leaves the least-squares fit out")
    parser.add_argument("--broyden-evaluations", type=int, default=16, quick=2,
                        help="trial points per start of the least-squares fit whose Jacobian "
                             "is simulated at its start and where the last served badly, "
                             f"Broyden-updated elsewhere (optimiser '{BROYDEN}'); 0 leaves "
                             "it out")
    parser.add_argument("--lm-iterations", type=int, default=4, quick=1,
                        help="batches of damped steps per start of the Levenberg-Marquardt "
                             f"fit (optimiser '{LEVENBERG_MARQUARDT}'): a Jacobian at the "
                             "start and where a batch improved, if another batch follows; 0 "
                             "leaves it out")
    parser.add_argument("--lm-batch", type=int, default=DEFAULT_LM_BATCH,
                        help=f"damped steps per batch, 1 to {MAX_LM_BATCH}, dampings a decade "
                             f"apart (default {DEFAULT_LM_BATCH})")
    parser.add_argument("--lm-broyden-iterations", type=int, default=4, quick=1,
                        help="batches per start of the Levenberg-Marquardt fit whose Jacobian "
                             "is simulated at its start and where the last served badly, "
                             f"Broyden-updated elsewhere (optimiser "
                             f"'{LEVENBERG_MARQUARDT_BROYDEN}'); 0 leaves it out")
    parser.add_argument("--lm-broyden-batch", type=int, default=DEFAULT_LATER_LM_BATCH,
                        help="damped steps per batch of that fit after a start's first (which "
                             f"has --lm-batch), 1 to {MAX_LM_BATCH} (default "
                             f"{DEFAULT_LATER_LM_BATCH})")
    parser.add_argument("--least-squares-method", default=DEFAULT_LEAST_SQUARES_METHOD,
                        choices=LEAST_SQUARES_METHODS,
                        help="scipy least_squares method of the least-squares fits (default "
                             f"{DEFAULT_LEAST_SQUARES_METHOD})")
    parser.add_argument("--cma-generations", type=int, default=8, quick=2,
                        help="CMA-ES generations")
    parser.add_argument("--polish-evaluations", type=int, default=0,
                        help="trial points of a least-squares fit from CMA-ES's best point "
                             f"(optimiser '{POLISH}', its costs counted on top of CMA-ES's); "
                             "0 (default) leaves it out")
    parser.add_argument("--popsize", type=int, default=None,
                        help="CMA-ES population, >= 2 (default cma's 4 + 3 ln D)")
    parser.add_argument("--sigma0", type=float, default=0.25,
                        help="CMA-ES's initial step in unit coordinates, in (0, 1] (default "
                             "0.25)")
    parser.add_argument("--start", default=None, metavar="CSV",
                        help="start every optimiser at the model of an earlier run's "
                             "identified.csv (model_select's) instead of --preset's")
    parser.add_argument("--held-out-gaits", default="", metavar="GAITS",
                        help="measured gaits, none of --gaits, on which the start and every "
                             "optimiser's best point are scored (gradient_fit_held_out.csv); "
                             "default none")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    return parser


def note_start_outside(name: str, box, base):
    """Name on stderr the axes of set `name`'s box whose value in the base model lies outside
    it: every fit starts at the nearest bound there (`identify.start_units`), not at the
    model's value (the delays of A3-A5 are 0 in every preset, and set 20fired's start at
    0.0005 s)."""
    outside = [f"{axis.label} = {axis.value_of(base):g} (starts at "
               f"{axis.values(axis.unit(axis.value_of(base))):g}, in [{axis.low:g}, "
               f"{axis.high:g}])" for axis in box
               if not axis.low <= axis.value_of(base) <= axis.high]
    if outside:
        print(f"gradient_fit: note: set {name}: the model lies outside the box in "
              f"{'; '.join(outside)}", file=sys.stderr)


def planned_instances(args, cma_settings, box, gaits, held_out_gaits) -> Tuple[int, str]:
    """(the instances one set's fits simulate at most, how they add up with the flags named):
    CMA-ES's generations × population; every call with sensitivities (two replicas per axis a
    fitted gait moves: the fits' evaluations, a second Jacobian per Broyden batch, the cost
    ratio's four, each optimiser's uncertainty); the plain runs (least squares' trial points,
    the batches' points, the cost ratio's four, each optimiser's validation and segments);
    each on every fitted gait, and each optimiser's point and the start on the held-out
    gaits."""
    moved_axes = len(box) - len(identify.unfired_axes(box, gaits))
    per_gradient = instances_per_instance(moved_axes)
    optimisers = 2 + sum(count > 0 for count in (
        args.least_squares_evaluations, args.broyden_evaluations, args.lm_iterations,
        args.lm_broyden_iterations, args.polish_evaluations))
    gradient = args.starts * (args.lbfgs_evaluations + args.least_squares_evaluations
                              + args.broyden_evaluations + args.lm_iterations
                              + 2 * args.lm_broyden_iterations) + args.polish_evaluations
    broyden_batches = (args.lm_batch + (args.lm_broyden_iterations - 1) * args.lm_broyden_batch
                       if args.lm_broyden_iterations else 0)
    plain = (cma_settings.evaluations(len(box))
             + args.starts * (args.least_squares_evaluations + args.broyden_evaluations
                              + args.lm_iterations * args.lm_batch + broyden_batches)
             + args.polish_evaluations)
    # the cost ratio's calls: each run once first, then COST_REPEATS times
    checks = (COST_REPEATS + 1) * (1 + per_gradient) + optimisers * (2 + per_gradient)
    count = ((plain + gradient * per_gradient + checks) * len(gaits)
             + (optimisers + 1) * len(held_out_gaits))
    return count, (
        f"(--cma-generations {args.cma_generations} × population "
        f"{cma_settings.population(len(box), 0)} + --starts {args.starts} × the fits' "
        f"evaluations and batch points + {gradient} calls with sensitivities × {per_gradient} "
        f"+ {checks} for the cost ratio, validation and uncertainty) × {len(gaits)} gaits"
        + (f" + {optimisers + 1} × {len(held_out_gaits)} held-out gaits" if held_out_gaits
           else ""))


def check_flags_of_fits_left_out(args):
    """StudyArgumentError for a setting changed from its default whose every fit is left out
    (its count flags at 0): it was taken and unused without a word (an audit, 2026-12), where
    the user most likely meant the fit to run."""
    least_squares_fits = (args.least_squares_evaluations, args.broyden_evaluations,
                          args.polish_evaluations)
    for flag, value, default, fits, counts in (
            ("--lm-batch", args.lm_batch, DEFAULT_LM_BATCH,
             "--lm-iterations and --lm-broyden-iterations",
             (args.lm_iterations, args.lm_broyden_iterations)),
            ("--lm-broyden-batch", args.lm_broyden_batch, DEFAULT_LATER_LM_BATCH,
             "--lm-broyden-iterations", (args.lm_broyden_iterations,)),
            ("--least-squares-method", args.least_squares_method,
             DEFAULT_LEAST_SQUARES_METHOD,
             "--least-squares-evaluations, --broyden-evaluations and --polish-evaluations",
             least_squares_fits)):
        if value != default and not any(counts):
            raise cli.StudyArgumentError(f"{flag} {value}: unused, {fits} at 0 leave out every "
                                         f"fit it sets")


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    sets = cli.parse_choices(args.sets, "--sets", list(PARAMETER_SETS))
    for flag, value in (("--starts", args.starts), ("--lbfgs-evaluations", args.lbfgs_evaluations),
                        ("--cma-generations", args.cma_generations)):
        if value < 1:
            raise cli.StudyArgumentError(f"{flag} must be >= 1, got {value}")
    for flag, value in (("--least-squares-evaluations", args.least_squares_evaluations),
                        ("--broyden-evaluations", args.broyden_evaluations),
                        ("--lm-iterations", args.lm_iterations),
                        ("--lm-broyden-iterations", args.lm_broyden_iterations),
                        ("--polish-evaluations", args.polish_evaluations)):
        if value < 0:
            raise cli.StudyArgumentError(f"{flag} must be >= 0, got {value}")
    for flag, value in (("--lm-batch", args.lm_batch),
                        ("--lm-broyden-batch", args.lm_broyden_batch)):
        cli.check_count(value, flag, 1, MAX_LM_BATCH)
    check_flags_of_fits_left_out(args)
    cma_settings = identify.CMASettings(popsize=args.popsize, max_generations=args.cma_generations,
                                        seed=args.seed, sigma0=args.sigma0)
    cma_settings.validate()
    train, validate = identify.parse_windows(args.train_cycles, args.validate_cycles)
    gaits = identify.measured_gaits(args.gaits)
    held_out_gaits = (identify.measured_gaits(args.held_out_gaits, "--held-out-gaits")
                      if args.held_out_gaits else [])
    fitted_too = [gait for gait in held_out_gaits if gait in gaits]
    if fitted_too:
        raise cli.StudyArgumentError(f"--held-out-gaits {', '.join(fitted_too)}: fitted as "
                                     f"well (--gaits {', '.join(gaits)}); a held-out gait must "
                                     f"be one the fits do not see")
    base = cli.base_params(args)
    if args.start is not None:
        base = identify.read_start(args.start, base, [
            cli.parse_assignment(item, "--set")[0] for item in args.set])
    boxes = {name: [identify.parse_range_spec(text, "--sets") for text in PARAMETER_SETS[name]]
             for name in sets}
    planned = {name: planned_instances(args, cma_settings, box, gaits, held_out_gaits)
               for name, box in boxes.items()}
    for name, (count, what) in planned.items():
        cli.check_instances(count, f"set {name}: {what}")
    total = sum(count for count, _ in planned.values())
    if len(planned) > 1:
        cli.check_instances(total, f"--sets {args.sets}: "
                                   + " + ".join(f"{count:,}" for count, _ in planned.values()))
    # every instance runs at most to the end of the longer window: a step too small for it is
    # refused, and the whole study's robot-steps checked (refused or estimated when long)
    # before any compute
    solver = cli.solver(args)
    cycles = max(train[1], validate[1])
    cli.check_run(f"--train-cycles {args.train_cycles} and --validate-cycles "
                  f"{args.validate_cycles} ({cycles:g} cycles, {cycles * base.period:.3g} s; "
                  f"{total:,} instances)", cycles * base.period, solver, batch=total,
                  arch=cli.work_arch(args), nodes=base.n_nodes)
    for box in boxes.values():  # every corner of each group of CORNER_GROUP axes (2^20 is
        for group in range(0, len(box), CORNER_GROUP):  # too many; the groups share no limit)
            identify.check_box(box[group:group + CORNER_GROUP], base, "--sets")
    trials = identification.measured_trials(gaits, base.period)
    identify.check_trials_cover(trials, validate, args.validate_cycles)
    held_out_trials = identification.measured_trials(held_out_gaits, base.period)
    # a held-out gait is scored on the training window
    identify.check_trials_cover(held_out_trials, train, args.train_cycles, "--train-cycles")
    # last of the checks: its notes on stderr come only before a run that starts
    for name, box in boxes.items():
        identify.check_unfired_axes("gradient_fit", f"set {name}", box, gaits)
        note_start_outside(name, box, base)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"gaits": gaits, "train_cycles": list(train),
                                           "validate_cycles": list(validate),
                                           "starts": args.starts,
                                           "lbfgs_evaluations": args.lbfgs_evaluations,
                                           "least_squares_evaluations":
                                               args.least_squares_evaluations,
                                           "least_squares_method": args.least_squares_method,
                                           "broyden_evaluations": args.broyden_evaluations,
                                           "lm_iterations": args.lm_iterations,
                                           "lm_batch": args.lm_batch,
                                           "lm_broyden_iterations": args.lm_broyden_iterations,
                                           "lm_broyden_batch": args.lm_broyden_batch,
                                           "cma_generations": args.cma_generations,
                                           "polish_evaluations": args.polish_evaluations,
                                           "popsize": args.popsize, "seed": args.seed,
                                           "sigma0": args.sigma0, "start": args.start,
                                           "held_out_gaits": held_out_gaits,
                                           "sets": {n: PARAMETER_SETS[n] for n in sets}})
    problems, recorders, cost_ratios = {}, [], {}

    def write_history():  # after every evaluation: an interrupted run keeps what it did
        out.write_csv(pd.DataFrame([row for r in recorders for row in r.rows]),
                      "gradient_fit_history.csv")

    for name in sets:
        problems[name] = Problem(boxes[name], base, gaits, trials, train, solver, args.arch)
        cma = Recorder(name, "CMA-ES", write_history)
        recorders.append(cma)
        fit_cma(problems[name], cma_settings, cma)
        cost_ratios[name] = measure_cost_ratio(problems[name])
        print(f"set {name}: a gradient call costs {cost_ratios[name]:.2f} runs", flush=True)
        recorders.append(Recorder(name, "L-BFGS-B", write_history))
        fit_lbfgs(problems[name], args.starts, args.lbfgs_evaluations, args.seed,
                  recorders[-1], cost_ratios[name])
        if args.least_squares_evaluations:
            recorders.append(Recorder(name, LEAST_SQUARES, write_history))
            fit_least_squares(problems[name], start_points(problems[name], args.starts,
                                                           args.seed),
                              args.least_squares_evaluations, recorders[-1], cost_ratios[name],
                              args.least_squares_method)
        if args.broyden_evaluations:
            recorders.append(Recorder(name, BROYDEN, write_history))
            fit_least_squares(problems[name], start_points(problems[name], args.starts,
                                                           args.seed),
                              args.broyden_evaluations, recorders[-1], cost_ratios[name],
                              args.least_squares_method, secant=True)
        if args.lm_iterations:
            recorders.append(Recorder(name, LEVENBERG_MARQUARDT, write_history))
            fit_levenberg_marquardt(problems[name], start_points(problems[name], args.starts,
                                                                 args.seed),
                                    args.lm_iterations, args.lm_batch, recorders[-1],
                                    cost_ratios[name])
        if args.lm_broyden_iterations:
            recorders.append(Recorder(name, LEVENBERG_MARQUARDT_BROYDEN, write_history))
            fit_levenberg_marquardt(problems[name], start_points(problems[name], args.starts,
                                                                 args.seed),
                                    args.lm_broyden_iterations, args.lm_batch, recorders[-1],
                                    cost_ratios[name], secant=True,
                                    later_batch=args.lm_broyden_batch)
        if args.polish_evaluations:
            recorders.append(Recorder.continuing(cma, POLISH, write_history))
            fit_least_squares(problems[name], [cma.best_units], args.polish_evaluations,
                              recorders[-1], cost_ratios[name], args.least_squares_method)
    table = summarise(recorders, problems, validate, cost_ratios)
    out.write_csv(table, "gradient_fit.csv")
    budgets = cma_budget_shares(recorders, {
        name: cma_settings.population(len(boxes[name]), 0) for name in sets})
    out.write_csv(budgets, "gradient_fit_cma_budgets.csv")
    if not budgets.empty:
        out.wrote(plot_cma_budgets(out.path("gradient_fit_cma_budgets.csv"),
                                   out.path("gradient_fit_cma_budgets.png")))
    out.write_csv(pd.concat([problems[r.parameter_set].uncertainty(r.best_units)
                             .assign(parameter_set=r.parameter_set, optimiser=r.optimiser)
                             for r in recorders], ignore_index=True)
                  [["parameter_set", "optimiser", *identification.UNCERTAINTY_COLUMNS]],
                  "gradient_fit_uncertainty.csv")
    if held_out_gaits:
        out.write_csv(pd.concat([held_out_scores(
            Problem(boxes[name], base, held_out_gaits, held_out_trials, train, solver,
                    args.arch), [r for r in recorders if r.parameter_set == name])
            for name in sets], ignore_index=True), "gradient_fit_held_out.csv")
    segments = pd.concat([segment_scores(problems[name], [r for r in recorders
                                                          if r.parameter_set == name])
                          for name in sets], ignore_index=True)
    if not segments.empty:
        out.write_csv(segments, "gradient_fit_segments.csv")
        out.wrote(plot_segments(out.path("gradient_fit_segments.csv"),
                                out.path("gradient_fit_segments.png")))
    out.wrote(plot_history(out.path("gradient_fit_history.csv"),
                           out.path("gradient_fit.png")))
    out.report()
    print(table.to_string(index=False))
    return table
