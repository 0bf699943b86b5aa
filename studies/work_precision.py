"""Work–precision: the time-step error and the discretisation error of the five paper gaits'
speeds over 3 cycles from rest, for the undamped (paper) and the damped (accurate) model, and
what each setting costs in run time.

    python -m studies work_precision [--out DIR] [--quick] [--arch cpu|gpu]
                                     [--gaits paper|A1,A1+A2,...] [--cycles 3] [--no-progress]

Models: "undamped" = `StarParams.preset("paper")` (no damping, clamped actuator ends,
limb-stiff joints; its preset mesh n_arc 18) and "damped" = `StarParams.preset("accurate")`
(damping time 0.94 ms, series joints, shared ends; n_arc 48), with n_arc varied.

Speed error of a run against a reference (`taichi_star.metrics.speed_error`):
|v − v_ref| / max(|v_ref|, 0.5 mm/s), v the signed
speed over `--cycles` cycles from rest (mm/s), so that a near-cancelling gait (A1 ≈ 0.1 mm/s)
is judged on an absolute 5 µm/s at 1 %. A configuration's error is the largest over the gaits
(NaN when an instance failed).

References (Richardson extrapolation over a ladder refined by 2 per level):
- time limit of a model: fixed-step BDF2 (Newton) on the preset mesh at the two finest h of
  `BDF2_H_MS`; space limit: fixed-step BDF2 at h = `SPACE_H_MS` on the two finest n_arc of
  `N_ARCS`. The limit is v_f + (v_f − v_m)/(2^p − 1), p the observed order of the ladder's three
  finest levels, log2(max_g |v_c − v_m| / max_g |v_m − v_f|) over the gaits, taken as at least 1
  (`MIN_ORDER`): below that the ladder is not in its asymptotic range, and p = 1 moves the limit
  no further from the finest run than the last change.
- continuum limit of a model: its space limit plus the time error of the space ladder's step
  measured on the preset mesh (time limit − the BDF2 run at `SPACE_H_MS` on the preset mesh).

Configurations (each one batch of the gaits): the time series on each model's preset mesh
(implicit Euler at `EULER_H_MS`, BDF2 at `BDF2_H_MS`, adaptive BDF2 with the chord Jacobian and
adaptive implicit Euler at `ERROR_TOLS`, adaptive BDF2 with Newton at the accurate preset's
tolerance), the space series (BDF2 at `SPACE_H_MS` over `N_ARCS`), and other meshes with the
presets' solvers (`MESH_N_ARCS`). Each is timed as one call after a one-step call has compiled
its engine. Time error: against its model's time limit (preset mesh only); space error:
against the space limit (space series only); total error: against the continuum limit.

The presets, `paper` (implicit Euler 1 ms, n_arc 18, undamped) and `accurate` (adaptive BDF2,
error_tol 1e-6 m, chord, n_arc 48, damped), are also timed at `TIMING_BATCH` instances (the
gaits repeated) in the same process, alternated `TIMING_ROUNDS` times after a compiling call,
the best of each kept; the machine and its load average are recorded.

Writes
- `work_precision.csv`: one row per configuration × gait: config, label, model, preset, series,
  n_arc, integrator, jacobian, stepping, h_ms (fixed step; the first step when adaptive),
  error_tol_m, gait, duration_s, signed_speed_mm_s, time_limit_mm_s, time_error,
  space_limit_mm_s, space_error, continuum_limit_mm_s, total_error, steps, rejected_steps,
  newton_iterations_mean, status, run_time_s (the batch of the gaits), robot_seconds_per_wall_s,
  machine, cpu_model, cores, commit, timestamp;
- `work_precision_summary.csv`: one row per configuration: the largest time, space and total
  errors and the gait of the largest total error, run time, robot-seconds per wall second,
  steps, Newton iterations, status, pareto (on its model's front of total error against run
  time); for the presets the `TIMING_BATCH` timing: timing_batch, timing_run_times_s,
  timing_robot_seconds_per_wall_s, ratio_to_paper, load_average_1min;
- `work_precision_references.csv`: per model, ladder (time, space) and gait the ladder's three
  finest levels and speeds, the gait's own observed order, the ladder's observed and used
  order, the limit and the finest run's error against it (the extrapolation); and the
  continuum limit (ladder "continuum");
- `work_precision.png`: total error against run time (Pareto fronts, paper and accurate
  marked), time error against h and against error_tol, space error against n_arc.

The robot-steps of every configuration and of the presets' timing together (adaptive ones at
their fewest) are refused past the library's limit, or estimated when long, before any run.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Optional

import numpy as np
import pandas as pd

import taichi_star
from taichi_star import SolverConfig, StarParams, fewest_steps, metrics
from taichi_star.profiling import interleaved_rounds
from taichi_star.timegrid import weighted_nodes

from . import cli, provenance

DESCRIPTION = ("Work–precision: time-step and discretisation errors of the five gaits' 3-cycle "
               "speeds (damped and undamped models) against Richardson limits, and run times.")

MODEL_PRESETS = {"undamped": "paper", "damped": "accurate"}
"""Model -> the StarParams preset that defines its physics (and its preset mesh)."""
MIN_ORDER = 1.0
"""Smallest order a Richardson extrapolation uses."""
REFINEMENT = 2.0
"""Ratio of successive levels of a ladder (h halved, n_arc doubled)."""

EULER_H_MS = (4.0, 2.0, 1.0, 0.5)
BDF2_H_MS = (4.0, 2.0, 1.0, 0.5, 0.25, 0.125)
"""Fixed steps, ms; the last three of BDF2_H_MS make the time ladder."""
ERROR_TOLS = (1e-5, 3e-6, 1e-6, 3e-7)
"""Adaptive tolerances, m (at 5e-8 m and below the adaptive stepper stalls just after the
second cycle starts: not used)."""
SPACE_H_MS = 0.25
N_ARCS = {"undamped": (18, 36, 72, 144), "damped": (18, 36, 72, 144)}
"""The space ladder's meshes (its last three make the ladder)."""
MESH_N_ARCS = {"undamped": (36, 72), "damped": (18, 24, 36, 72)}
"""Other meshes, run with their model's preset solver (the damped ones also at error_tol
`MESH_ERROR_TOL`)."""
MESH_ERROR_TOL = 3e-6
"""The other adaptive tolerance of the damped meshes, m (the accurate preset's own is 1e-6)."""
ACCURATE_SOLVER = SolverConfig.preset("accurate")
TIMING_BATCH = 64
TIMING_ROUNDS = 2

QUICK_DURATION_S = 0.15
QUICK_GAITS = ("A1+A2", "A1+A3")
QUICK_EULER_H_MS = ()
QUICK_BDF2_H_MS = (2.0, 1.0, 0.5)
QUICK_ERROR_TOLS = ()
"""--quick: no Euler ladder and no extra tolerances (the presets' own configurations stay: the
paper's Euler, the accurate adaptive BDF2): each would compile an engine or an adaptive kernel
of its own, while the rows go through the same code as the BDF2 ladder's."""
QUICK_SPACE_H_MS = 1.0
QUICK_N_ARCS = {"undamped": (9, 18, 36), "damped": (12, 24, 48)}
"""Each model's ladder holds its preset's mesh (18, 48): its bdf2 engine serves both."""
QUICK_TIMING_BATCH = 8


@dataclass(frozen=True)
class Grid:
    """The configurations' axes (full or --quick). Steps in ms, tolerances in m."""

    euler_h_ms: tuple
    bdf2_h_ms: tuple
    error_tols: tuple
    space_h_ms: float
    n_arcs: dict
    mesh_n_arcs: dict
    timing_batch: int


FULL_GRID = Grid(EULER_H_MS, BDF2_H_MS, ERROR_TOLS, SPACE_H_MS, N_ARCS, MESH_N_ARCS, TIMING_BATCH)
QUICK_GRID = Grid(QUICK_EULER_H_MS, QUICK_BDF2_H_MS, QUICK_ERROR_TOLS, QUICK_SPACE_H_MS,
                  QUICK_N_ARCS, {"undamped": (), "damped": ()}, QUICK_TIMING_BATCH)


@dataclass(frozen=True)
class Config:
    """One model, mesh and solver."""

    model: str
    n_arc: int
    solver: SolverConfig

    def params(self, gaits):
        """One instance per gait."""
        return [StarParams.preset(MODEL_PRESETS[self.model], gait=g, n_arc=self.n_arc)
                for g in gaits]

    @property
    def nodes(self) -> int:
        """The robot's nodes (`StarParams.n_nodes`)."""
        return StarParams.preset(MODEL_PRESETS[self.model], n_arc=self.n_arc).n_nodes

    @property
    def preset_mesh(self) -> int:
        """n_arc of the model's preset."""
        return StarParams.preset(MODEL_PRESETS[self.model]).n_arc

    def preset(self) -> str:
        """"paper" or "accurate" when this is that preset's model, mesh and solver, else ""."""
        name = MODEL_PRESETS[self.model]
        return name if self == preset_config(self.model) else ""

    def label(self) -> str:
        """e.g. "bdf2 h=0.5ms", "bdf2 tol=3e-06 chord", "euler h=1ms n_arc=72" (fixed steps:
        Newton's method)."""
        s = self.solver
        parts = ([s.integrator, f"tol={s.error_tol:.0e}", s.jacobian] if s.adaptive
                 else [s.integrator, f"h={s.dt * 1e3:g}ms"])
        if self.n_arc != self.preset_mesh:
            parts.append(f"n_arc={self.n_arc}")
        return " ".join(parts)


def fixed(integrator: str, h_ms: float) -> SolverConfig:
    """Fixed steps of h_ms milliseconds, Newton's method."""
    return SolverConfig(integrator=integrator, dt=h_ms * 1e-3)


def adaptive(integrator: str, error_tol: float, jacobian: str) -> SolverConfig:
    """The accurate preset's adaptive stepping (first step 1 ms) with another integrator,
    tolerance (m) or Jacobian."""
    return ACCURATE_SOLVER.replace(integrator=integrator, error_tol=error_tol, jacobian=jacobian)


def preset_config(model: str) -> Config:
    """The model's preset: its StarParams and SolverConfig presets."""
    name = MODEL_PRESETS[model]
    return Config(model, StarParams.preset(name).n_arc, SolverConfig.preset(name))


def time_ladder(model: str, grid: Grid):
    """The time ladder's configurations, coarse to fine."""
    mesh = preset_config(model).n_arc
    return [Config(model, mesh, fixed("bdf2", h)) for h in grid.bdf2_h_ms[-3:]]


def space_ladder(model: str, grid: Grid):
    """The space ladder's configurations, coarse to fine."""
    return [Config(model, n, fixed("bdf2", grid.space_h_ms)) for n in grid.n_arcs[model][-3:]]


def configurations(grid: Grid):
    """Every configuration of both models, deduplicated, in running order."""
    configs = []
    for model in MODEL_PRESETS:
        mesh = preset_config(model).n_arc
        configs.append(preset_config(model))
        configs += [Config(model, mesh, fixed("euler", h)) for h in grid.euler_h_ms]
        configs += [Config(model, mesh, fixed("bdf2", h)) for h in grid.bdf2_h_ms]
        configs += [Config(model, mesh, adaptive("bdf2", tol, "chord")) for tol in grid.error_tols]
        configs += [Config(model, mesh, adaptive("euler", tol, "newton"))
                    for tol in grid.error_tols]
        configs.append(Config(model, mesh, adaptive("bdf2", ACCURATE_SOLVER.error_tol,
                                                    "newton")))
        configs += [Config(model, n, fixed("bdf2", grid.space_h_ms)) for n in grid.n_arcs[model]]
        for n in grid.mesh_n_arcs[model]:
            configs.append(Config(model, n, preset_config(model).solver))
            if model == "damped":
                configs.append(Config(model, n, adaptive("bdf2", MESH_ERROR_TOL, "chord")))
    return list(dict.fromkeys(configs))


# --------------------------------------------------------------------------- errors, references

def observed_order(coarse, middle, fine) -> float:
    """Observed order of a ladder (levels refined by REFINEMENT) from its three finest levels'
    speeds (arrays over the gaits), pooled over the gaits: `metrics.observed_order` of the
    largest change between the coarser pair and the largest between the finer pair. A
    heuristic for the extrapolation's order: the two largest changes may be two gaits'
    (each gait's own order is `gait_order` in the table)."""
    coarse_change = np.max(np.abs(np.asarray(coarse) - np.asarray(middle)))
    fine_change = np.max(np.abs(np.asarray(middle) - np.asarray(fine)))
    return float(metrics.observed_order(coarse_change, fine_change, REFINEMENT))


def order_used(observed: float) -> float:
    """The order a Richardson extrapolation uses: the observed one, at least MIN_ORDER."""
    return observed if observed >= MIN_ORDER else MIN_ORDER


def ladder_reference(model, ladder, levels, speeds, gaits):
    """Rows of the references table for one ladder and its limit per gait. levels: the three
    finest (h in ms or n_arc), speeds: their (3, gaits) signed speeds, mm/s."""
    coarse, middle, fine = speeds
    observed = observed_order(coarse, middle, fine)
    used = order_used(observed)
    limit = metrics.richardson_limit(middle, fine, used, REFINEMENT)
    # the signed changes: their magnitudes read an oscillating ladder as converging (A1+A4's
    # undamped time ladder 0.865, 0.901, 0.847 gave an order; an audit, 2026-12)
    gait_orders = metrics.observed_order(middle - coarse, fine - middle, REFINEMENT)
    return pd.DataFrame({
        "model": model, "ladder": ladder, "gait": gaits,
        "refined": "h_ms" if ladder == "time" else "n_arc",
        "coarse": levels[0], "middle": levels[1], "fine": levels[2],
        "coarse_speed_mm_s": coarse, "middle_speed_mm_s": middle, "fine_speed_mm_s": fine,
        "gait_order": gait_orders, "observed_order": observed, "order_used": used,
        "limit_mm_s": limit, "fine_error": metrics.speed_error(fine, limit)})


def references(speeds, grid: Grid, gaits):
    """The references table: the time and space ladders' limits and the continuum limit of
    each model. speeds: Config -> signed speeds over the gaits, mm/s."""
    parts = []
    for model in MODEL_PRESETS:
        time_configs, space_configs = time_ladder(model, grid), space_ladder(model, grid)
        time_part = ladder_reference(model, "time", [c.solver.dt * 1e3 for c in time_configs],
                                     np.array([speeds[c] for c in time_configs]), gaits)
        space_part = ladder_reference(model, "space", [c.n_arc for c in space_configs],
                                      np.array([speeds[c] for c in space_configs]), gaits)
        on_preset_mesh = Config(model, preset_config(model).n_arc, space_configs[0].solver)
        step_time_error = time_part["limit_mm_s"].to_numpy() - speeds[on_preset_mesh]
        continuum = space_part["limit_mm_s"].to_numpy() + step_time_error
        parts += [time_part, space_part,
                  pd.DataFrame({"model": model, "ladder": "continuum", "gait": gaits,
                                "limit_mm_s": continuum})]
    return pd.concat(parts, ignore_index=True)


# --------------------------------------------------------------------------- runs

def check_whole_run(configs, n_gaits: int, timing_batch: int, duration_s: float,
                    length: str, arch: Optional[str] = None):
    """Refuse or estimate (`cli.check_steps`) the robot-steps of the whole study before any
    run: each configuration's batch of the gaits (a one-step compiling call, then duration_s)
    and the presets' timing (`time_presets`: timing_batch instances, a one-step call and
    TIMING_ROUNDS runs each). Adaptive steps counted at their fewest (`fewest_steps`). Each
    call stayed under the warning: --gaits all --cycles 1000 started 5.6e10 robot-steps without
    a word (an audit, 2026-12), each configuration's weighed by its mesh (`nodes`; the space
    ladder's finest, n_arc 144, six times the paper robot's). `arch`: whose bound
    (`cli.work_arch`)."""
    def steps(solver):
        return fewest_steps(solver, duration_s, 0.0)[0]
    presets = [preset_config(model) for model in MODEL_PRESETS]
    # (robot-steps, nodes) of each part: the configurations' batches, the presets' timing
    parts = ([(n_gaits * (1 + steps(config.solver)), config.nodes) for config in configs]
             + [(timing_batch * (1 + TIMING_ROUNDS * steps(config.solver)), config.nodes)
                for config in presets])
    cli.check_robot_steps(f"{len(configs)} configurations × {n_gaits} gait(s) and the presets' "
                          f"timing at {timing_batch} instances × {TIMING_ROUNDS} rounds, {length}",
                          sum(count for count, _ in parts), arch, weighted_nodes(parts))


def run_config(config: Config, gaits, duration_s, arch):
    """(summary, run time s) of one batch of the gaits: a one-step call compiles, then the
    timed call simulates duration_s (`profiling.interleaved_rounds`, one round)."""
    params = config.params(gaits)
    solver = config.solver
    results, times, _ = interleaved_rounds(
        [lambda: taichi_star.simulate(params, duration_s, solver, arch=arch, progress=False)], 1,
        [lambda: taichi_star.simulate(params, solver.dt, solver, arch=arch, progress=False)])
    return results[0].summary, float(times[0, 0])


def time_presets(gaits, duration_s, batch, arch):
    """Run times (s) of `batch` instances (the gaits repeated) of each preset, its model's
    configuration and solver, in alternation TIMING_ROUNDS times after one compiling call each
    (`profiling.interleaved_rounds`); and the 1-minute load average just before the first timed
    call."""
    calls, warmups = [], []
    for model in MODEL_PRESETS:
        config = preset_config(model)
        params = config.params([gaits[i % len(gaits)] for i in range(batch)])
        calls.append(lambda params=params, solver=config.solver: taichi_star.simulate(
            params, duration_s, solver, arch=arch, progress=False))
        warmups.append(lambda params=params, solver=config.solver: taichi_star.simulate(
            params, solver.dt, solver, arch=arch, progress=False))
    load = []
    _, times, _ = interleaved_rounds(calls, TIMING_ROUNDS, warmups,
                                     before_rounds=lambda: load.append(os.getloadavg()[0]))
    run_times = {MODEL_PRESETS[model]: times[:, index].tolist()
                 for index, model in enumerate(MODEL_PRESETS)}
    return run_times, load[0]


def series_of(config: Config, grid: Grid) -> str:
    """"time" (the preset mesh), "space" (the space series), "time+space" (both: the space
    series' run on the preset mesh) or "mesh" (another mesh)."""
    in_space = (config.solver == fixed("bdf2", grid.space_h_ms)
                and config.n_arc in grid.n_arcs[config.model])
    on_preset_mesh = config.n_arc == config.preset_mesh
    return {(True, True): "time+space", (True, False): "space", (False, True): "time",
            (False, False): "mesh"}[(in_space, on_preset_mesh)]


def config_rows(config: Config, grid: Grid, summary: pd.DataFrame, run_time: float,
                duration_s: float) -> pd.DataFrame:
    """The rows of one configuration, before the errors."""
    solver = config.solver
    return pd.DataFrame({
        "label": config.label(), "model": config.model, "preset": config.preset(),
        "series": series_of(config, grid), "n_arc": config.n_arc,
        "integrator": solver.integrator, "jacobian": solver.jacobian,
        "stepping": "adaptive" if solver.adaptive else "fixed", "h_ms": solver.dt * 1e3,
        "error_tol_m": solver.error_tol if solver.adaptive else math.nan,
        "gait": summary["gait"].to_numpy(), "duration_s": duration_s,
        "signed_speed_mm_s": summary["signed_speed_mm_s"].to_numpy(dtype=float),
        "steps": summary["steps"].to_numpy(),
        "rejected_steps": summary["rejected_steps"].to_numpy(),
        "newton_iterations_mean": summary["newton_iterations_mean"].to_numpy(),
        "status": summary["status"].to_numpy(), "run_time_s": run_time,
        "robot_seconds_per_wall_s": len(summary) * duration_s / run_time})


def add_errors(table: pd.DataFrame, refs: pd.DataFrame) -> pd.DataFrame:
    """The limit and error columns of every row: time (preset mesh only), space (space series
    only) and total (against the continuum limit); NaN for a failed instance."""
    table = table.copy()
    limit_of = {(model, ladder, gait): limit for model, ladder, gait, limit in
                refs[["model", "ladder", "gait", "limit_mm_s"]].itertuples(index=False)}
    failed = table["status"] != "ok"
    # (ladder, error column, the series it applies to: "" = every series)
    for ladder, error, member in (("time", "time_error", "time"),
                                  ("space", "space_error", "space"),
                                  ("continuum", "total_error", "")):
        limit = np.array([limit_of[(model, ladder, gait)] if member in series else math.nan
                          for model, gait, series in
                          table[["model", "gait", "series"]].itertuples(index=False)])
        table[f"{ladder}_limit_mm_s"] = limit
        table[error] = np.where(failed, math.nan,
                                metrics.speed_error(table["signed_speed_mm_s"], limit))
    return table


def pareto_front(run_time, error) -> np.ndarray:
    """Mask of the points no other point beats in both run time and error (NaN error: never on
    the front)."""
    run_time, error = np.asarray(run_time, float), np.asarray(error, float)
    mask = np.zeros(len(run_time), dtype=bool)
    best = math.inf
    for index in np.lexsort((error, run_time)):
        if np.isfinite(error[index]) and error[index] < best:
            mask[index] = True
            best = error[index]
    return mask


def largest(errors: pd.Series) -> float:
    """The largest error over the gaits; NaN when any is NaN (not in the series, or failed)."""
    return float(errors.max()) if errors.notna().all() else math.nan


SUMMARY_KEYS = ["config", "label", "model", "preset", "series", "n_arc", "integrator",
                "jacobian", "stepping", "h_ms", "error_tol_m"]


def summarise(table: pd.DataFrame, run_times, load_average: float, batch: int) -> pd.DataFrame:
    """One row per configuration; the presets' rows with their timing at `batch` instances
    (run_times: preset -> wall times, s, of its timed calls)."""
    rows = []
    for _, part in table.groupby("config", sort=True):
        first = part.iloc[0]
        total = part["total_error"]
        rows.append({**{key: first[key] for key in SUMMARY_KEYS},
                     "max_time_error": largest(part["time_error"]),
                     "max_space_error": largest(part["space_error"]),
                     "max_total_error": largest(total),
                     "worst_gait": part["gait"].iloc[int(np.argmax(total.to_numpy()))]
                     if total.notna().all() else "",
                     "run_time_s": first["run_time_s"],
                     "robot_seconds_per_wall_s": first["robot_seconds_per_wall_s"],
                     "steps_mean": part["steps"].mean(),
                     "newton_iterations_mean": part["newton_iterations_mean"].mean(),
                     "status": ",".join(sorted(set(part["status"])))})
    summary = pd.DataFrame(rows)
    summary["pareto"] = False
    for _, part in summary.groupby("model"):
        summary.loc[part.index, "pareto"] = pareto_front(part["run_time_s"],
                                                         part["max_total_error"])
    duration = table["duration_s"].iloc[0]
    rate = {name: batch * duration / min(times) for name, times in run_times.items()}
    is_preset = summary["preset"] != ""
    summary["timing_batch"] = np.where(is_preset, batch, 0)
    summary["timing_run_times_s"] = [";".join(f"{t:.3f}" for t in run_times[p]) if p else ""
                                     for p in summary["preset"]]
    summary["timing_robot_seconds_per_wall_s"] = [rate.get(p, math.nan)
                                                  for p in summary["preset"]]
    summary["ratio_to_paper"] = summary["timing_robot_seconds_per_wall_s"] / rate["paper"]
    summary["load_average_1min"] = np.where(is_preset, load_average, math.nan)
    return summary


# --------------------------------------------------------------------------- plot

FAMILIES = {("fixed", "euler", "newton"): ("implicit Euler, fixed h", "tab:red"),
            ("fixed", "bdf2", "newton"): ("BDF2, fixed h", "tab:blue"),
            ("adaptive", "bdf2", "chord"): ("BDF2 adaptive, chord", "tab:green"),
            ("adaptive", "bdf2", "newton"): ("BDF2 adaptive, Newton", "tab:olive"),
            ("adaptive", "euler", "newton"): ("implicit Euler adaptive", "tab:orange")}
"""(stepping, integrator, jacobian) -> legend name and colour."""
MODEL_MARKERS = {"undamped": "s", "damped": "o"}


def plot_work_precision(summary_csv, png_path):
    """Total error against run time (the presets marked), time error against h and against
    error_tol, space error against n_arc."""
    plt = cli.use_agg()
    summary = pd.read_csv(summary_csv)
    summary["preset"] = summary["preset"].fillna("")
    fig = plt.figure(figsize=(16, 11), layout="constrained")
    grid = fig.add_gridspec(2, 3)
    pareto = fig.add_subplot(grid[0, :2])
    by_h, by_tol, by_mesh = (fig.add_subplot(grid[1, column]) for column in range(3))

    for (stepping, integrator, jacobian), part in summary.groupby(
            ["stepping", "integrator", "jacobian"], sort=False):
        name, colour = FAMILIES[(stepping, integrator, jacobian)]
        for model, points in part.groupby("model", sort=False):
            pareto.plot(points["run_time_s"], points["max_total_error"],
                        MODEL_MARKERS[model], color=colour, ms=6, alpha=0.8,
                        mfc=colour if model == "damped" else "none",
                        label=f"{name}, {model}")
    for model, part in summary.groupby("model", sort=False):
        front = part[part["pareto"]].sort_values("run_time_s")
        pareto.step(front["run_time_s"], front["max_total_error"], where="post", color="k",
                    lw=0.8, ls="-" if model == "damped" else "--",
                    label=f"Pareto front, {model}")
    for ax in (pareto, by_h, by_tol, by_mesh):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
    pareto.axhline(0.01, color="k", ls=":", lw=1)
    pareto.autoscale_view()
    presets = summary[summary["preset"] != ""].set_index("preset")
    data_to_axes = pareto.transData + pareto.transAxes.inverted()
    for name, row in presets.iterrows():
        point = (row["run_time_s"], row["max_total_error"])
        pareto.plot(*point, "*", ms=18, mfc="gold", mec="k", zorder=5)
        # the label goes toward the middle of the panel, away from the edges
        x, y = data_to_axes.transform(point)
        pareto.annotate(
            f"{name}: {row['label']}, n_arc {row['n_arc']}\n"
            f"max error {row['max_total_error']:.2%} vs the {row['model']} limit\n"
            f"{row['timing_robot_seconds_per_wall_s']:.0f} robot-s/s at B = "
            f"{row['timing_batch']}", point,
            xytext=(40 if x < 0.5 else -40, 50 if y < 0.5 else -50), textcoords="offset points",
            ha="left" if x < 0.5 else "right", va="center",
            fontsize=8, bbox={"boxstyle": "round", "fc": "white", "ec": "0.6", "alpha": 0.85},
            arrowprops={"arrowstyle": "->", "color": "0.3"})
    pareto.set_xlabel("run time of one batch of the gaits (s)")
    pareto.set_ylabel("max speed error over the gaits vs the model's continuum limit")
    pareto.set_title("total error against run time (dotted: 1 %)", fontsize=9)

    fixed_steps = summary[summary["series"].str.contains("time")
                          & (summary["stepping"] == "fixed")]
    for (model, integrator), part in fixed_steps.groupby(["model", "integrator"], sort=False):
        part = part.sort_values("h_ms")
        by_h.plot(part["h_ms"], part["max_time_error"], MODEL_MARKERS[model] + "-",
                  color=FAMILIES[("fixed", integrator, "newton")][1],
                  mfc="none" if model == "undamped" else None,
                  label=f"{integrator}, {model} (n_arc {part['n_arc'].iloc[0]})")
    by_h.set_xlabel("time step h (ms)")
    by_h.set_ylabel("max speed error vs the time limit")
    by_h.set_title("time-step error, fixed steps, preset mesh", fontsize=9)

    tolerances = summary[summary["series"].str.contains("time")
                         & (summary["stepping"] == "adaptive")]
    for (model, integrator, jacobian), part in tolerances.groupby(
            ["model", "integrator", "jacobian"], sort=False):
        part = part.sort_values("error_tol_m")
        name, colour = FAMILIES[("adaptive", integrator, jacobian)]
        by_tol.plot(part["error_tol_m"], part["max_time_error"], MODEL_MARKERS[model] + "-",
                    color=colour, mfc="none" if model == "undamped" else None,
                    label=f"{name}, {model}")
    by_tol.set_xlabel("error_tol (m)")
    by_tol.set_ylabel("max speed error vs the time limit")
    by_tol.set_title("time-step error, adaptive steps, preset mesh", fontsize=9)

    space = summary[summary["series"].str.contains("space")]
    for model, part in space.groupby("model", sort=False):
        part = part.sort_values("n_arc")
        by_mesh.plot(part["n_arc"], part["max_space_error"], MODEL_MARKERS[model] + "-",
                     color="k", mfc="none" if model == "undamped" else None,
                     label=f"{model}, BDF2 h = {part['h_ms'].iloc[0]:g} ms")
    by_mesh.set_xlabel("n_arc (edges per actuator arc)")
    by_mesh.set_ylabel("max speed error vs the space limit")
    by_mesh.set_title("discretisation error (limit: the two finest meshes)", fontsize=9)

    for ax, values in ((by_h, fixed_steps["h_ms"]), (by_mesh, space["n_arc"])):
        values = sorted(set(values))
        ax.set_xticks(values, [f"{v:g}" for v in values])
        ax.xaxis.set_minor_locator(plt.NullLocator())
    legend_panel = fig.add_subplot(grid[0, 2])
    legend_panel.axis("off")
    legend_panel.legend(*pareto.get_legend_handles_labels(), fontsize=8, loc="center left")
    for ax in (by_h, by_tol, by_mesh):
        ax.legend(fontsize=7)
    cli.write_figure(fig, png_path, dpi=110)
    plt.close(fig)
    return png_path


# --------------------------------------------------------------------------- command line

def build_parser():
    parser = cli.StudyParser("work_precision", DESCRIPTION)
    parser.add_argument("--gaits", default="paper", quick=",".join(QUICK_GAITS),
                        help=cli.GAITS_HELP)
    cli.add_cycles_flag(parser, default=3.0, quick_s=QUICK_DURATION_S)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    gaits = cli.resolve_gaits(args.gaits)
    grid = QUICK_GRID if args.quick else FULL_GRID
    duration = (QUICK_DURATION_S if args.quick
                else args.cycles * StarParams.preset("paper").period)
    configs = configurations(grid)
    # the finest fixed step of the grid takes the most steps, the coarsest the fewest
    fixed_steps = [config.solver.dt for config in configs if not config.solver.adaptive]
    length = (f"--quick ({duration:g} s)" if args.quick
              else f"--cycles {args.cycles:g} ({duration:.3g} s)")
    cli.check_length(length, duration, min(fixed_steps), "the grid's finest step")
    cli.check_one_step(length, duration, max(fixed_steps), "the grid's coarsest step")
    check_whole_run(configs, len(gaits), grid.timing_batch, duration, length,
                    cli.work_arch(args))
    out = cli.Output(args, argv or [], model={"models": MODEL_PRESETS, "gaits": gaits},
                     solver={"grid": grid, "configurations": [c.label() for c in configs]})
    machine = provenance.machine_columns(args.arch)
    # taken before the runs: the code that ran, not what the tree became meanwhile
    provenance_columns = {"machine": machine["machine"], "cpu_model": machine["cpu_model"],
                          "cores": machine["cores"], "commit": provenance.short_commit(),
                          "timestamp": out.provenance["date"]}
    load_at_start = os.getloadavg()

    bar = None
    if not args.no_progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=len(configs) + 1, unit="run", desc="work-precision")
    parts, speeds = [], {}
    for config in configs:
        if bar is not None:
            bar.set_postfix_str(f"{config.model} {config.label()}")
        with cli.batch_work_told():  # told by `check_whole_run`: not again for each call
            summary, run_time = run_config(config, gaits, duration, args.arch)
        speeds[config] = summary["signed_speed_mm_s"].to_numpy(dtype=float)
        parts.append(config_rows(config, grid, summary, run_time, duration))
        if bar is not None:
            bar.update()
    if bar is not None:
        bar.set_postfix_str(f"presets at B = {grid.timing_batch}")
    with cli.batch_work_told():
        run_times, load_average = time_presets(gaits, duration, grid.timing_batch, args.arch)
    if bar is not None:
        bar.update()
        bar.close()

    refs = references(speeds, grid, gaits)
    table = pd.concat(parts, ignore_index=True)
    table.insert(0, "config", np.repeat(np.arange(len(parts)), len(gaits)))
    table = add_errors(table, refs)
    for name, value in provenance_columns.items():
        table[name] = value
    summary = summarise(table, run_times, load_average, grid.timing_batch)
    for name, value in provenance_columns.items():
        summary[name] = value
    timing = {"timing_batch": grid.timing_batch, "timing_rounds": TIMING_ROUNDS,
              "preset_run_times_s": run_times, "load_average_at_start": load_at_start,
              "load_average_before_timing_1min": load_average,
              "load_average_at_end": os.getloadavg()}
    out.write_csv(table, "work_precision.csv", extra=timing)
    summary_path = out.write_csv(summary, "work_precision_summary.csv", extra=timing)
    out.write_csv(refs, "work_precision_references.csv")
    out.wrote(plot_work_precision(summary_path, out.path("work_precision.png")))
    report(summary, refs)
    out.report()
    return table, summary, refs


def report(summary: pd.DataFrame, refs: pd.DataFrame):
    """Print the orders of the ladders, the configurations by model and run time, and the
    presets' timing."""
    print("\nRichardson ladders (observed order -> order used):")
    ladders = refs[refs["ladder"] != "continuum"].groupby(["model", "ladder"], sort=False).first()
    for (model, ladder), row in ladders.iterrows():
        print(f"  {model:<9} {ladder:<5} {row['refined']} {row['coarse']:g}, {row['middle']:g}, "
              f"{row['fine']:g}: order {row['observed_order']:.2f} -> {row['order_used']:.2f}")
    print(f"\n{'model':<9} {'configuration':<30} {'time err':>9} {'space err':>9} "
          f"{'total err':>9} {'run s':>7} {'robot-s/s':>9}")
    for _, row in summary.sort_values(["model", "run_time_s"]).iterrows():
        mark = f"  <- {row['preset']}" if row["preset"] else ""
        print(f"{row['model']:<9} {row['label']:<30} {row['max_time_error']:9.2e} "
              f"{row['max_space_error']:9.2e} {row['max_total_error']:9.2e} "
              f"{row['run_time_s']:7.2f} {row['robot_seconds_per_wall_s']:9.1f}{mark}")
    for _, row in summary[summary["preset"] != ""].iterrows():
        print(f"{row['preset']}: {row['timing_robot_seconds_per_wall_s']:.1f} robot-s/s at "
              f"B = {row['timing_batch']} (runs {row['timing_run_times_s']} s), "
              f"{row['ratio_to_paper']:.2f}x paper")
