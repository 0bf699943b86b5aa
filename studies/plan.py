"""Planner: drive the simulated robot to goal points by choosing a gait every cycle from the
motion primitives, open loop (a plan made at the start, fired blindly) and closed loop
(re-planned each cycle from the simulated state); every goal x both controllers in one batch.

    python -m studies plan [--primitives CSV] [--distance 50] [--directions 8] [--far 150]
                           [--tolerance 5] [--max-cycles 25] [--cycles 5] [--set NAME=VALUE]
                           [--discretisation paper|converged] [--dt S] [--arch cpu|gpu]
                           [--out DIR] [--quick]

Goals: --directions points at --distance mm in every direction (0°, 45°, ... for 8), plus one
--far mm straight behind the robot (0: none). The primitive table is read from --primitives
(a `python -m studies primitives` CSV made with the same period and step) or measured first
(--cycles cycles from rest, statistics from the second cycle on).

Writes into --out (default a fresh runs/plan/<timestamp>/), each CSV with a JSON sidecar:
- `plan.csv`: per goal and controller (`taichi_star.planner.PLAN_COLUMNS`): reached,
  cycles_to_goal, cycles_fired, final_error_mm (when the controller stopped), end_error_mm
  (when the batch stopped: the robot glides on after its last firing), status;
- `plan_gain.csv`: open against closed loop: goals reached, mean and largest final error,
  mean cycles to the goal where both reached it;
- `plan_cycles.csv`: the state at each cycle boundary, the gait fired and the model's
  prediction; `plan_paths.csv`: the centroid paths;
- `primitives.csv` when measured here; `plan.png`: the paths, drawn from the CSVs.

--quick: dt = 5 ms, 2 cycles of primitives, at most 2 cycles of driving.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.params import SolverConfig
from taichi_star.planner import PrimitiveModel, closed_loop_gain, default_goals, drive
from taichi_star.primitives import measure_primitives

from . import common

DESCRIPTION = ("Drive the robot to goal points by choosing a gait per cycle from the motion "
               "primitives: open loop against closed loop, in one batch.")
QUICK = {"dt": 5e-3, "cycles": 2, "max_cycles": 2}


def plot_paths(paths_csv, plan_csv, png_path):
    """The centroid paths of both controllers (open dashed, closed solid; where each stopped:
    o reached, x not; then the glide, dotted) and the goals (stars), from plan_paths.csv and
    plan.csv."""
    plt = common.use_agg()
    paths = pd.read_csv(paths_csv)
    plan = pd.read_csv(plan_csv)
    fig, ax = plt.subplots(figsize=(7.0, 6.4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    goals = plan.drop_duplicates("goal")
    for i, goal in enumerate(goals.itertuples()):
        colour = colours[i % len(colours)]
        for mode, style in (("open", "--"), ("closed", "-")):
            path = paths[(paths["goal"] == goal.goal) & (paths["mode"] == mode)]
            row = plan[(plan["goal"] == goal.goal) & (plan["mode"] == mode)].iloc[0]
            controlled = path[path["controlled"]]
            ax.plot(controlled["x_mm"], controlled["y_mm"], style, color=colour, lw=1.1,
                    label=None if i else f"{mode} loop")
            ax.plot(controlled["x_mm"].iloc[-1], controlled["y_mm"].iloc[-1],
                    "o" if row["reached"] else "x", color=colour, ms=4)
            gliding = path[path["t_s"] >= controlled["t_s"].iloc[-1]]
            ax.plot(gliding["x_mm"], gliding["y_mm"], ":", color=colour, lw=0.7, alpha=0.6,
                    label=None if i or mode == "open" else "gliding after the stop")
        ax.plot(goal.goal_x_mm, goal.goal_y_mm, "*", color=colour, ms=11, mec="k", mew=0.5)
    ax.plot(0, 0, "k+", ms=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    gain = plan.groupby("mode")["final_error_mm"].mean()
    ax.set_title(f"Paths to {len(goals)} goals (stars): open loop dashed, closed loop solid, "
                 f"gliding dotted\n"
                 f"mean final error: open {gain.get('open', np.nan):.1f} mm, closed "
                 f"{gain.get('closed', np.nan):.1f} mm; o = reached, x = not", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def build_parser():
    parser = common.common_parser("plan", DESCRIPTION)
    parser.set_defaults(out=None)
    parser.add_argument("--primitives", default=None, metavar="CSV",
                        help="primitive table to plan with (default: measure it first)")
    parser.add_argument("--distance", type=float, default=50.0,
                        help="distance of the goals around the robot, mm (default 50)")
    parser.add_argument("--directions", type=int, default=8,
                        help="goals at --distance, equally spaced in direction (default 8)")
    parser.add_argument("--far", type=float, default=150.0,
                        help="distance of the goal straight behind, mm (default 150; 0: none)")
    parser.add_argument("--tolerance", type=float, default=5.0,
                        help="a goal is reached within this distance, mm (default 5)")
    parser.add_argument("--max-cycles", type=int, default=None,
                        help=f"cycle budget per goal (default 25; --quick {QUICK['max_cycles']})")
    parser.add_argument("--cycles", type=int, default=None,
                        help=f"cycles of the primitive measurement when no --primitives is "
                             f"given (default 5; --quick {QUICK['cycles']})")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override one StarParams field, e.g. --set alpha=1.0")
    return parser


def read_primitives(path, period: float, dt: float) -> pd.DataFrame:
    """A primitive CSV made at this period and step (StudyArgumentError naming --primitives
    otherwise)."""
    try:
        table = pd.read_csv(path)
    except (OSError, ValueError) as error:
        raise common.StudyArgumentError(f"--primitives {path}: {error}") from None
    needed = {"gait", "step_x_mm", "step_y_mm", "turn_deg", "status", "period_s", "dt_s"}
    if not needed <= set(table.columns):
        raise common.StudyArgumentError(f"--primitives {path}: not a primitives table (needs "
                                        f"{sorted(needed)})")
    made = (float(table["period_s"].iloc[0]), float(table["dt_s"].iloc[0]))
    if not np.allclose(made, (period, dt), rtol=1e-12, atol=0):
        raise common.StudyArgumentError(f"--primitives {path}: made at period {made[0]} s, "
                                        f"dt {made[1]} s; this run has {period} s, {dt} s")
    return table


def main(argv=None):
    argv = list(argv or [])
    args = build_parser().parse_args(argv)
    max_cycles = args.max_cycles if args.max_cycles is not None else (
        QUICK["max_cycles"] if args.quick else 25)
    cycles = args.cycles if args.cycles is not None else (QUICK["cycles"] if args.quick else 5)
    for value, flag, lowest in ((max_cycles, "--max-cycles", 1), (cycles, "--cycles", 2),
                                (args.directions, "--directions", 0)):
        if value < lowest:
            raise common.StudyArgumentError(f"{flag} must be >= {lowest}, got {value}")
    common.check_positive(args.distance, "--distance")
    common.check_positive(args.tolerance, "--tolerance")
    if not (np.isfinite(args.far) and args.far >= 0):
        raise common.StudyArgumentError(f"--far must be >= 0, got {args.far}")
    if args.directions == 0 and args.far == 0:
        raise common.StudyArgumentError("no goals: --directions 0 and --far 0")
    overrides = common.parse_overrides(args.set)
    if "gait" in overrides:
        raise common.StudyArgumentError("--set gait=...: the planner chooses the gaits")
    try:
        base = common.base_params(args).replace(**overrides)
        solver = SolverConfig(dt=args.dt if args.dt is not None else
                              (QUICK["dt"] if args.quick else 1e-3))
    except (ValueError, TypeError) as error:
        raise common.StudyArgumentError(f"invalid parameter value: {error}") from None
    goals = default_goals(args.distance, args.directions, args.far or None)
    if args.primitives is not None:
        primitives = read_primitives(args.primitives, base.period, solver.dt)
    out = common.fresh_output(args, "plan")
    details = {"overrides": overrides, "discretisation": args.discretisation,
               "tolerance_mm": args.tolerance, "max_cycles": max_cycles,
               "primitives": args.primitives or "measured in this run"}
    paths = []
    try:
        if args.primitives is None:
            primitives, _ = measure_primitives(base, solver, cycles=cycles, first_cycle=1,
                                               arch=args.arch, progress=not args.no_progress)
            paths.append(common.write_table(primitives, out / "primitives.csv", "plan", argv,
                                            details))
        summary, per_cycle, path = drive(PrimitiveModel.from_table(primitives), goals, base,
                                         solver, tolerance_mm=args.tolerance,
                                         max_cycles=max_cycles, arch=args.arch,
                                         progress=not args.no_progress)
    except ValueError as error:
        raise common.StudyArgumentError(str(error)) from None
    gain = pd.DataFrame([closed_loop_gain(summary)])
    paths += [common.write_table(summary, out / "plan.csv", "plan", argv, details),
              common.write_table(gain, out / "plan_gain.csv", "plan", argv, details),
              common.write_table(per_cycle, out / "plan_cycles.csv", "plan", argv, details),
              common.write_table(path, out / "plan_paths.csv", "plan", argv, details)]
    paths.append(plot_paths(paths[-1], paths[-4], out / "plan.png"))
    print(common.describe(paths))
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(summary.to_string(index=False))
        print(gain.T.to_string(header=False))
    return summary
