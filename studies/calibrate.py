"""Calibration: fit StarParams fields to the measured speeds of the paper's gaits with CMA-ES.

    python -m studies calibrate [--fit NAME=LOW:HIGH[:log] ...]
                                [--preset paper|accurate|identified]
                                [--set NAME=VALUE ...] [--gaits paper|A1,A1+A2,...]
                                [--weights experimental|uniform] [--popsize P]
                                [--max-generations G] [--restarts R] [--seed S] [--sigma0 0.25]
                                [--cycles 3] [--dt S] [--cross-validate] [--arch cpu|gpu]
                                [--out DIR] [--quick] [--workers N | --scheduler tcp://HOST:PORT]

CMA-ES (`cma.CMAEvolutionStrategy`, ask/tell) searches the box of the `--fit` ranges in unit
coordinates: every axis is mapped to [0, 1] (`:log` axes in the logarithm), the optimiser keeps
its candidates inside [0, 1] (cma's bound transformation) and a parameter value is always
computed from its unit coordinate (`studies.identify.ParameterRange.values`), so every value
tried lies in its range. Each generation is one batched run (`taichi_star.batch.run_batch`): all
candidates × all gaits. The first run starts at the `--preset`/`--set` model's coordinates
(clipped into the box) with step `--sigma0`; each of `--restarts` further runs starts at a
uniformly random point with twice the previous population (IPOP), seeded from `--seed`. The
objective is the weighted mean squared relative signed-speed error against the measured speeds
with the paper's directions as signs (`studies.identify`); a candidate whose simulation fails
scores inf (CMA-ES is told `FAILED_PENALTY`).

Writes into `--out` (default a fresh `runs/calibrate/<timestamp>/`), each table with its
provenance sidecar (`.csv.json`): `calibration.csv` (every evaluation, rewritten after each
generation), `calibration_best.csv` (the best point: its values and objective, the five gaits'
signed speeds, speed ratios and directions there, `all_directions_match`, and the run's
settings), `calibration.png` (convergence), and Fig. 4c/4b at the best point
(`fig4c_calibrated.*`, `fig4b_calibrated.*`).

`--cross-validate`: for every gait, fit on the others and predict it: `crossval.csv` (every fold ×
gait: measured and predicted signed speed, role held_out / fitted), `crossval_evaluations.csv`,
`crossval.png` (predicted against measured).
"""

from __future__ import annotations

import dataclasses
import math
import textwrap
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import pandas as pd

from taichi_star import SolverConfig, StarParams, experiment

from . import cli, figures, identify
from .identify import DEFAULT_MAX_GENERATIONS, CMASettings, best_row, best_units

DESCRIPTION = ("Fit StarParams fields to the measured speeds and directions of the paper's gaits "
               "with CMA-ES (one batched simulation per generation); --cross-validate: "
               "leave-one-gait-out.")

DEFAULT_FIT = ["alpha=0.2:1.5", "added_mass_coeff=0:3", "drag_perpendicular=0.3:3:log",
               "drag_parallel=0.001:0.1:log", "cylinder_drag=1:100:log",
               "limb_stiffness_ratio=10:1000:log"]
"""The default six axes: jet ratio, added mass, rod drag (both), cylinder drag, limb stiffness,
each spanning the paper's value by about a factor of 3-10 either way."""
QUICK_FIT = ["alpha=0.2:1.5", "cylinder_drag=1:100:log"]
DEFAULT_CYCLES = 3.0
"""Cycles from rest of every evaluation of `fit_cmaes` when its run_kwargs give no run length
(the Fig. 4c metric)."""
QUICK_POPSIZE, QUICK_MAX_GENERATIONS = 4, 2


def fit_cmaes(box: Sequence[identify.ParameterRange], base: StarParams,
              measurements: pd.DataFrame, settings: CMASettings = CMASettings(),
              run_kwargs: dict = None, progress: bool = False,
              on_generation: Callable[[pd.DataFrame], None] = None) -> pd.DataFrame:
    """Minimise `experiment.objective_values` over the box with CMA-ES (`identify.minimise_cmaes`,
    from the base model's coordinates) and return every evaluation: columns evaluation,
    restart, generation, candidate, then those of `identify.evaluate_points`. `run_kwargs`:
    keyword arguments of `taichi_star.batch.run_batch` (run length, solver, arch, executor,
    chunk size; default DEFAULT_CYCLES cycles from rest in this process).
    `on_generation(table so far)` is called after each generation (e.g. to write the CSV)."""
    identify.check_box(box, base)
    run_kwargs = dict(run_kwargs or {"cycles": DEFAULT_CYCLES})
    return identify.minimise_cmaes(
        box, identify.start_units(box, base),
        lambda units: identify.evaluate_points(box, units, base, measurements, run_kwargs),
        settings, progress=progress, on_generation=on_generation).evaluations


# --------------------------------------------------------------------------- cross-validation

def cross_validate(box, base: StarParams, gaits: Sequence[str], weights: str,
                   settings: CMASettings, run_kwargs: dict, progress: bool = False):
    """Leave one gait out: for each gait, fit on the others (`fit_cmaes`), then simulate every
    fold's best point on all `gaits` in one batch. Returns (predictions, evaluations):
    predictions has one row per fold × gait (held_out_gait, gait, role "held_out" or "fitted",
    measured_signed_mm_s, cycle_std_mm_s, predicted_signed_mm_s, predicted_over_measured,
    direction_matches, status, fit_objective, the fitted values); evaluations is every
    evaluation of every fold with a held_out_gait column."""
    gaits = list(gaits)
    if len(gaits) < 2:
        raise cli.StudyArgumentError("--cross-validate: needs at least two gaits in --gaits")
    folds, units, objectives = [], [], []
    for held_out in gaits:
        fitted = [g for g in gaits if g != held_out]
        evaluations = fit_cmaes(box, base, experiment.measurement_table(fitted, weights), settings,
                                run_kwargs, progress=progress)
        evaluations.insert(0, "held_out_gait", held_out)
        folds.append(evaluations)
        row = best_row(evaluations)
        if row is None:  # every candidate failed: predict nothing for this fold
            units.append(np.full(len(box), np.nan))
            objectives.append(math.inf)
            continue
        units.append(best_units(evaluations, box))
        objectives.append(float(row["objective"]))
    measured = experiment.measurement_table(gaits, weights)
    runnable = [i for i, u in enumerate(units) if np.isfinite(u).all()]
    predicted = (identify.evaluate_points(box, [units[i] for i in runnable], base, measured,
                                          run_kwargs) if runnable else None)
    rows = []
    for position, held_out in enumerate(gaits):
        point = (predicted.iloc[runnable.index(position)] if position in runnable else None)
        for gait in gaits:
            target = float(measured.loc[gait, "target_signed_mm_s"])
            value = float(point[f"signed_speed_{gait}"]) if point is not None else math.nan
            rows.append({
                "held_out_gait": held_out, "gait": gait,
                "role": "held_out" if gait == held_out else "fitted",
                "measured_signed_mm_s": target,
                "cycle_std_mm_s": float(measured.loc[gait, "cycle_std_mm_s"]),
                "predicted_signed_mm_s": value, "predicted_over_measured": value / target,
                "direction_matches": bool(np.sign(value) == np.sign(target)),
                "status": point["status"] if point is not None else "fit_failed",
                "fit_objective": objectives[position],
                **{spec.column: (float(point[spec.column]) if point is not None else math.nan)
                   for spec in box}})
    return pd.DataFrame(rows), pd.concat(folds, ignore_index=True)


# --------------------------------------------------------------------------- plots (from CSVs)

def draw_convergence(evaluations: pd.DataFrame, box: Sequence[identify.ParameterRange]):
    """Figure of a calibration run: top, the objective of every evaluation (dots, coloured by
    restart) and the best so far (line), log scale, against evaluation number; bottom, the
    best-so-far point's unit coordinates, one line per fitted axis of the `box` (axis [0, 1]),
    read from the table's columns of that axis (`ParameterRange.key`, `.column`: an element
    axis NAME[INDEX] has columns of its own)."""
    plt = cli.use_agg()
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.5), sharex=True)
    objective = evaluations["objective"].astype(float).to_numpy()
    finite = np.isfinite(objective)
    best_so_far = np.minimum.accumulate(np.where(finite, objective, np.inf))
    top.scatter(evaluations["evaluation"][finite], objective[finite],
                c=evaluations["restart"][finite], cmap="viridis", s=10, label="evaluation")
    top.step(evaluations["evaluation"], best_so_far, where="post", color="tab:red",
             label="best so far")
    positive = objective[finite & (objective > 0)]
    if len(positive):
        top.set_yscale("log")
        top.set_ylim(positive.min() / 1.5, positive.max() * 1.5)
    top.set_ylabel("objective (weighted mean r²)")
    top.legend(fontsize=8)
    # unit coordinates of the incumbent after each evaluation
    best_index = np.zeros(len(objective), dtype=int)
    for i in range(1, len(objective)):
        best_index[i] = i if objective[i] < objective[best_index[i - 1]] else best_index[i - 1]
    for spec in box:
        bottom.plot(evaluations["evaluation"],
                    evaluations[f"u_{spec.key}"].to_numpy()[best_index], label=spec.label)
    bottom.set_ylim(-0.02, 1.02)
    bottom.set_ylabel("best point, unit coordinate")
    bottom.set_xlabel("evaluation")
    bottom.legend(fontsize=7, ncol=2)
    if finite.any():
        row = best_row(evaluations)
        fitted = textwrap.fill(", ".join(f"{spec.label} = {row[spec.column]:.4g}"
                                         for spec in box), width=100)
        top.set_title(f"CMA-ES calibration, best point:\n{fitted}\nobjective "
                      f"{row['objective']:.4g}, direction mismatches "
                      f"{int(row['n_direction_mismatches'])}", fontsize=8)
    fig.tight_layout()
    return fig


def plot_convergence(csv_path, png_path, box: Sequence[identify.ParameterRange]) -> Path:
    fig = draw_convergence(pd.read_csv(csv_path), box)
    cli.write_figure(fig, png_path, dpi=130)
    cli.use_agg().close(fig)
    return Path(png_path)


def plot_cross_validation(csv_path, png_path) -> Path:
    """Predicted against measured signed speed from a crossval CSV: each fold's held-out gait
    (large, x error bar = per-cycle std of the measurement) and its fitted gaits (small, grey);
    the diagonal is a perfect prediction, the shaded quadrants a wrong direction."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    fig, ax = plt.subplots(figsize=(6.2, 5.6))
    fitted = table[table["role"] == "fitted"]
    ax.scatter(fitted["measured_signed_mm_s"], fitted["predicted_signed_mm_s"], s=12,
               color="0.6", label="fitted gaits (in sample)")
    held = table[table["role"] == "held_out"]
    for _, row in held.iterrows():
        ax.errorbar(row["measured_signed_mm_s"], row["predicted_signed_mm_s"],
                    xerr=row["cycle_std_mm_s"], fmt="o", ms=7, capsize=3,
                    label=f"{row['gait']} held out")
    reach = np.concatenate([table["measured_signed_mm_s"].abs() + table["cycle_std_mm_s"],
                            table["predicted_signed_mm_s"].abs()]).astype(float)
    limit = 1.1 * np.nanmax(reach) if np.isfinite(reach).any() else 1.0  # error bars included
    ax.plot([-limit, limit], [-limit, limit], "k--", lw=0.8)
    ax.fill_between([0, limit], -limit, 0, color="red", alpha=0.06, lw=0)
    ax.fill_between([-limit, 0], 0, limit, color="red", alpha=0.06, lw=0)
    ax.set_xlim(-limit, limit)
    ax.set_ylim(-limit, limit)
    ax.axhline(0, color="k", lw=0.5)
    ax.axvline(0, color="k", lw=0.5)
    ax.set_xlabel("measured signed speed (mm/s; sign = paper's direction)")
    ax.set_ylabel("predicted signed speed (mm/s)")
    settings = cli.run_settings(csv_path)
    ax.set_title("leave-one-gait-out: fit on the others, predict the held-out gait\n"
                 + (f"{settings}; " if settings else "") + "red quadrants: wrong direction",
                 fontsize=9)
    ax.legend(fontsize=7)
    return cli.save_figure(fig, png_path)


# --------------------------------------------------------------------------- CLI

def build_parser():
    parser = cli.StudyParser("calibrate", DESCRIPTION)
    parser.add_argument("--fit", action="append", metavar="NAME=LOW:HIGH[:log]",
                        default=DEFAULT_FIT, quick=QUICK_FIT,
                        help="a real-valued StarParams field and its bounds, repeatable")
    parser.add_argument("--gaits", default="paper",
                        help="measured gaits to fit: paper (all five, default) or a comma list")
    parser.add_argument("--weights", choices=experiment.WEIGHT_SCHEMES, default="experimental",
                        help="experimental: gait weight ∝ (speed / per-cycle std)² (default); "
                             "uniform: all 1")
    parser.add_argument("--popsize", type=int, default=None, quick=QUICK_POPSIZE,
                        help="CMA-ES population, >= 2 (none: cma's 4 + 3 ln D), doubled at "
                             "each restart")
    parser.add_argument("--max-generations", type=int, default=DEFAULT_MAX_GENERATIONS,
                        quick=QUICK_MAX_GENERATIONS, help="generations per CMA-ES run, >= 1")
    parser.add_argument("--restarts", type=int, default=0,
                        help=f"extra CMA-ES runs from random points, population doubled (IPOP; at "
                             f"most {identify.MAX_RESTARTS})")
    parser.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    parser.add_argument("--sigma0", type=float, default=0.25,
                        help="initial CMA-ES step in unit coordinates, in (0, 1] (default 0.25)")
    parser.add_argument("--cross-validate", action="store_true",
                        help="leave one gait out: fit on the others, predict it, for every gait")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    cli.add_execution_flags(parser)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    settings = CMASettings(popsize=args.popsize, max_generations=args.max_generations,
                           restarts=args.restarts, seed=args.seed, sigma0=args.sigma0)
    settings.validate()
    gaits = identify.measured_gaits(args.gaits)
    if args.cross_validate and len(gaits) < 2:
        raise cli.StudyArgumentError("--cross-validate: needs at least two gaits in --gaits")
    box = [identify.parse_range_spec(text, "--fit") for text in args.fit]
    # a cross-validation fits each gait's fold on the others, then predicts the held-out one
    fitted, folds = (len(gaits) - 1, len(gaits)) if args.cross_validate else (len(gaits), 1)
    cli.check_instances(
        (settings.evaluations(len(box)) * fitted + (len(gaits) if folds > 1 else 0)) * folds,
        f"--max-generations {settings.max_generations} × the population "
        f"({settings.population(len(box), 0)}, doubled at each of --restarts {settings.restarts}) "
        f"× {fitted} gaits" + (f" (and the held-out one's prediction) × {folds} folds"
                               if folds > 1 else ""))
    base = identify.model_with_box(args, box, "--fit")
    identify.check_unfired_axes("calibrate", "--fit", box, gaits)
    measurements = experiment.measurement_table(gaits, args.weights)
    solver = cli.solver(args, periods=cli.range_periods(box))
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"fit": [spec.spec for spec in box], "gaits": gaits,
                                           "weights": args.weights,
                                           "cma": dataclasses.asdict(settings)})
    progress = not args.no_progress
    with cli.executor(args, out) as executor:
        generation_size = settings.population(len(box), 0) * len(gaits)
        # no bar per evaluation: the fit's own bar counts its generations (and --no-progress
        # means none at all)
        run_kwargs = dict(**cli.run_length(args), solver=solver, arch=args.arch,
                          executor=executor, progress=False,
                          chunk_size=cli.chunk_size(args, generation_size, executor.n_workers))
        if args.cross_validate:
            return _cross_validation_outputs(out, box, base, gaits, args.weights, settings,
                                             run_kwargs, progress)
        evaluations = fit_cmaes(box, base, measurements, settings, run_kwargs, progress=progress,
                                on_generation=lambda table: out.write_csv(table,
                                                                          "calibration.csv"))
    csv = out.path("calibration.csv")
    out.wrote(plot_convergence(csv, out.path("calibration.png"), box))
    row = best_row(evaluations)
    if row is None:
        out.report()
        print("calibration: every candidate failed; no fit")
        return evaluations
    # an element axis NAME[INDEX] sets one number of its field's tuple (`point_changes`; a
    # replace by name failed on it, after the whole fit: an audit, 2026-12)
    best = {spec.label: float(row[spec.column]) for spec in box}
    calibrated = base.replace(**identify.point_changes(box, list(best.values()), base))
    duration = cli.duration_s(args, calibrated.period)
    note = "calibrated (" + ", ".join(f"{n}={v:.3g}" for n, v in best.items()) + ")"
    table4c = figures.run_fig4c(out, calibrated, solver, duration_s=duration, arch=args.arch,
                                prefix="fig4c_calibrated", progress=progress, title_note=note)
    out.write_csv(best_point_table(row, box, table4c, args, settings, solver, duration, gaits,
                                   len(evaluations)), "calibration_best.csv")
    out.report()
    print("best: " + ", ".join(f"{n} = {v:.6g}" for n, v in best.items())
          + f" (objective {row['objective']:.4g} on {', '.join(gaits)})")
    print(table4c.to_string(index=False))
    wrong = table4c[~table4c["direction_matches"].astype(bool)]["gait"].tolist()
    print("gaits whose direction disagrees with the paper at the best point: "
          + (", ".join(wrong) if wrong else "none (all five match)"))
    return evaluations


def best_point_table(row: pd.Series, box, table4c: pd.DataFrame, args, settings: CMASettings,
                     solver: SolverConfig, duration_s: float, gaits: Sequence[str],
                     n_evaluations: int) -> pd.DataFrame:
    """One row: the best point (values, objective, where it was found), the five paper gaits at
    that point (signed speed in mm/s, speed ratio to the experiment, direction match, and
    all_directions_match, from the Fig. 4c run made at that point afterwards: with adaptive
    steps up to 0.3 % off the evaluation's own speeds, whose objective the row records) and
    the run's settings (duration_s and dt_s in s; cycles NaN under --quick, which runs a
    duration)."""
    record = {"evaluation": int(row["evaluation"]), "restart": int(row["restart"]),
              "generation": int(row["generation"]), "objective": float(row["objective"]),
              **{spec.column: float(row[spec.column]) for spec in box}}
    for _, gait_row in table4c.iterrows():
        gait = gait_row["gait"]
        record[f"signed_speed_{gait}"] = gait_row["sim_signed_speed_mm_s"]
        record[f"speed_ratio_{gait}"] = gait_row["speed_ratio"]
        record[f"direction_matches_{gait}"] = bool(gait_row["direction_matches"])
    record["all_directions_match"] = bool(table4c["direction_matches"].astype(bool).all())
    record.update({
        "fit_box": " ".join(spec.spec for spec in box), "fixed": " ".join(args.set),
        # --quick runs a duration (duration_s), not cycles: 3 was recorded (an audit, 2026-12)
        "gaits": " ".join(gaits), "weights": args.weights,
        "cycles": math.nan if args.quick else args.cycles,
        "duration_s": duration_s, "dt_s": solver.dt, "preset": args.preset,
        "seed": settings.seed, "popsize": settings.population(len(box), 0),
        "restarts": settings.restarts, "max_generations": settings.max_generations,
        "sigma0": settings.sigma0, "n_evaluations": n_evaluations})
    return pd.DataFrame([record])


def _cross_validation_outputs(out: cli.Output, box, base: StarParams, gaits: Sequence[str],
                              weights: str, settings: CMASettings, run_kwargs: dict,
                              progress: bool) -> pd.DataFrame:
    predictions, evaluations = cross_validate(box, base, gaits, weights, settings, run_kwargs,
                                              progress=progress)
    csv = out.write_csv(predictions, "crossval.csv")
    out.write_csv(evaluations, "crossval_evaluations.csv")
    out.wrote(plot_cross_validation(csv, out.path("crossval.png")))
    out.report()
    held = predictions[predictions["role"] == "held_out"]
    print(held[["gait", "measured_signed_mm_s", "predicted_signed_mm_s",
                "predicted_over_measured", "direction_matches", "fit_objective"]]
          .to_string(index=False))
    return predictions
