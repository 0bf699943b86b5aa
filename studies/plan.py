"""Planner: drive the simulated robot to goal points by choosing a gait every cycle from the
motion primitives, open loop (a plan made at the start, fired blindly) and closed loop
(re-planned each cycle from the simulated state); every goal x both controllers in one batch.

    python -m studies plan [--primitives CSV] [--distance 50] [--directions 8] [--far 150]
                           [--tolerance 5] [--max-cycles 25] [--cycles 5]
                           [--glide-cycles 4] [--settle-cycles 4]
                           [--lookahead [--lookahead-gaits all|A1,A1+A2,...] [--resume]]
                           [--preset paper|accurate|identified] [--set NAME=VALUE ...] [--dt S]
                           [--arch cpu|gpu] [--out DIR] [--quick]

--lookahead also drives the same goals by the full model's lookahead
(`taichi_star.lookahead.lookahead_drive`): every cycle each robot's present is copied into one
robot per candidate (the glide and --lookahead-gaits, default all 255), each fires its gait,
swims the cycle and coasts --settle-cycles cycles, and the robot takes the future that comes to
rest nearest its goal, stopping once the glide comes to rest within --tolerance; no primitives,
judged as the planner's. It writes lookahead.csv, lookahead_cycles.csv, lookahead_paths.csv and
controllers.csv (open, closed and lookahead side by side), and draws its paths in plan.png.
After every decision the lookahead so far is written to resume/lookahead.npz in --out (removed
once its tables are written): a run killed or stopped with Ctrl-C is continued from its last
decision, bit for bit, by the same command with --resume (the primitives' loops run again to
the same bits, and their measurement where no --primitives table is given); without --resume a
run into that folder is refused.

Goals: --directions points at --distance mm in every direction (0°, 45°, ... for 8), plus one
--far mm straight behind the robot (0: none). The primitive table is read from --primitives
(a `python -m studies primitives` CSV made with the same period and step) or measured first
(--cycles cycles from rest, statistics from the second cycle on, and each gait's glide after
k = 1..--cycles firings in a row over --glide-cycles cycles; both flags of the measurement
are refused with --primitives). The planner follows how many
cycles in a row a gait has fired (the robot builds up momentum: steps and glides grow over
the first cycles) and plans for the glide (it stops firing when the robot would coast to rest
within the tolerance; primitives without glide columns: no glide); after the last controller
stops the robots coast --settle-cycles cycles, and a goal is judged by where the robot comes
to rest, --settle-cycles cycles after its own controller stopped.

Writes into --out (default a fresh runs/plan/<timestamp>/), each CSV with its provenance
sidecar (`.csv.json`):
- `plan.csv`: per goal and controller (`taichi_star.planner.PLAN_COLUMNS`): reached (at
  rest within the tolerance), cycles_to_goal, cycles_fired, final_error_mm (when the
  controller stopped, still gliding), end_error_mm (at rest), status;
- `plan_gain.csv`: open against closed loop: goals reached, mean and largest final error,
  mean cycles to the goal where both reached it;
- `plan_cycles.csv`: the state at each cycle boundary, the gait fired and the model's
  prediction; `plan_paths.csv`: the centroid paths (10 records a cycle, or the most below
  that split the cycle into whole steps: 9 at 2 ms);
- `primitives.csv` when measured here; `plan.png`: the paths, drawn from the CSVs.

--quick: dt = 5 ms, 2 cycles of primitives and one of glide, at most 2 cycles of driving and
one of settling.
"""

from __future__ import annotations

import argparse
import functools
import hashlib
from pathlib import Path
from typing import Optional

import numpy as np
import pandas as pd

from taichi_star import StarParams
from taichi_star.lookahead import check_lookahead, compare_controllers, lookahead_drive
from taichi_star.planner import (SETTLE_CYCLES, PrimitiveModel, closed_loop_gain, drive)
from taichi_star.primitives import GLIDE_CYCLES, measure_primitives

from . import cli, provenance

DESCRIPTION = ("Drive the robot to goal points by choosing a gait per cycle from the motion "
               "primitives: open loop against closed loop, in one batch.")
QUICK_DT = 5e-3
QUICK_CYCLES = 2
QUICK_MAX_CYCLES = 2
QUICK_GLIDE_CYCLES = QUICK_SETTLE_CYCLES = 1
QUICK_LOOKAHEAD_GAITS = "A1,A2,A3,A4,A5,A6,A7,A8"
PRIMITIVES_FIRST_CYCLE = 1
"""Primitives measured here: statistics from the second cycle on."""


class MeasurementFlag(argparse.Action):
    """Stores a flag of the primitives' measurement and notes it in args.measurement_flags:
    --primitives replaces that measurement, and a flag given with it would be ignored."""

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, values)
        namespace.measurement_flags = [*namespace.measurement_flags, option_string]


CONTROLLER_STYLES = {"open": "--", "closed": "-", "lookahead": "-."}
"""How plan.png draws each controller's path."""
CONTROLLER_LABELS = {"open": "open loop", "closed": "closed loop", "lookahead": "lookahead"}


def plot_paths(paths_csv, plan_csv, png_path, lookahead=None) -> Path:
    """The centroid paths of the controllers (open dashed, closed solid, with --lookahead the
    lookahead dash-dotted; where each stopped: o reached, x not; then the glide, dotted) and the
    goals (stars), from plan_paths.csv and plan.csv, and lookahead = (lookahead_paths.csv,
    lookahead.csv) where given."""
    plt = cli.use_agg()
    paths = pd.read_csv(paths_csv)
    plan = pd.read_csv(plan_csv)
    if lookahead is not None:
        paths = pd.concat([paths, pd.read_csv(lookahead[0])], ignore_index=True)
        plan = pd.concat([plan, pd.read_csv(lookahead[1])], ignore_index=True)
    modes = [mode for mode in CONTROLLER_STYLES if mode in set(plan["mode"])]
    fig, ax = plt.subplots(figsize=(7.0, 6.4))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    goals = plan.drop_duplicates("goal")
    for i, goal in enumerate(goals.itertuples()):
        colour = colours[i % len(colours)]
        for mode in modes:
            path = paths[(paths["goal"] == goal.goal) & (paths["mode"] == mode)]
            row = plan[(plan["goal"] == goal.goal) & (plan["mode"] == mode)].iloc[0]
            controlled = path[path["controlled"]]
            ax.plot(controlled["x_mm"], controlled["y_mm"], CONTROLLER_STYLES[mode],
                    color=colour, lw=1.1, label=None if i else CONTROLLER_LABELS[mode])
            ax.plot(controlled["x_mm"].iloc[-1], controlled["y_mm"].iloc[-1],
                    "o" if row["reached"] else "x", color=colour, ms=4)
            gliding = path[path["t_s"] >= controlled["t_s"].iloc[-1]]
            ax.plot(gliding["x_mm"], gliding["y_mm"], ":", color=colour, lw=0.7, alpha=0.6,
                    label=None if i or mode != "closed" else "gliding after the stop")
        ax.plot(goal.goal_x_mm, goal.goal_y_mm, "*", color=colour, ms=11, mec="k", mew=0.5)
    ax.plot(0, 0, "k+", ms=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    errors = plan.groupby("mode")["final_error_mm"].mean()
    styles = {"--": "dashed", "-": "solid", "-.": "dash-dotted"}
    ax.set_title(f"Paths to {len(goals)} goals (stars): "
                 + ", ".join(f"{CONTROLLER_LABELS[mode]} {styles[CONTROLLER_STYLES[mode]]}"
                             for mode in modes)
                 + ", gliding dotted\nmean final error: "
                 + ", ".join(f"{mode} {errors.get(mode, np.nan):.1f} mm" for mode in modes)
                 + "; o = reached, x = not", fontsize=9)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return cli.save_figure(fig, png_path)


def build_parser():
    parser = cli.StudyParser("plan", DESCRIPTION)
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser, quick=QUICK_DT)
    parser.add_argument("--primitives", default=None, metavar="CSV",
                        help="primitive table to plan with (default: measure it first)")
    cli.add_goal_flags(parser, directions=8, far_mm=150.0)
    parser.add_argument("--max-cycles", type=int, default=25, quick=QUICK_MAX_CYCLES,
                        help="cycle budget per goal")
    parser.add_argument("--cycles", type=int, default=5, quick=QUICK_CYCLES,
                        action=MeasurementFlag,
                        help="cycles of the primitive measurement (not with --primitives)")
    parser.add_argument("--glide-cycles", type=int, default=GLIDE_CYCLES,
                        quick=QUICK_GLIDE_CYCLES, action=MeasurementFlag,
                        help="cycles of coasting of the glide measurement (0: plan without "
                             "glide; not with --primitives)")
    parser.set_defaults(measurement_flags=[])
    parser.add_argument("--settle-cycles", type=int, default=SETTLE_CYCLES,
                        quick=QUICK_SETTLE_CYCLES,
                        help="cycles the robots coast to rest after the last controller stops")
    parser.add_argument("--lookahead", action="store_true",
                        help="also drive the goals by the full model's lookahead (every "
                             "candidate gait simulated from the robot's own state each cycle, "
                             "to rest; no primitives): lookahead*.csv, controllers.csv")
    parser.add_argument("--lookahead-gaits", default=None,
                        help=f"the lookahead's candidates besides the glide: "
                             f"{cli.GAITS_HELP} (default all; --quick: the eight single "
                             f"actuators)")
    parser.add_argument("--resume", action="store_true",
                        help="with --lookahead and --out: continue the lookahead of the run in "
                             "--out from its last decision (resume/lookahead.npz)")
    return parser


LOOKAHEAD_CHECKPOINT = "resume/lookahead.npz"
"""Where in --out the lookahead keeps its checkpoint until its tables are written."""


def open_checkpoint(out: "cli.Output", resume: bool, check) -> Path:
    """The lookahead's checkpoint in the run's folder, checked before any compute: one there
    (a run killed) is continued with --resume, whose lookahead `check(checkpoint=...)` must
    accept (StudyArgumentError naming --resume otherwise), and refused without it, as the
    fresh run would write over it; --resume with none says so and starts afresh."""
    checkpoint = out.folder / LOOKAHEAD_CHECKPOINT
    out.resume_records = checkpoint.parent
    if checkpoint.exists() and not resume:
        raise cli.StudyArgumentError(f"--out {out.folder} holds an unfinished lookahead "
                                     f"({checkpoint}): --resume continues it; remove that file "
                                     f"to start afresh")
    if resume and checkpoint.exists():
        try:
            check(checkpoint=checkpoint)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--resume: {error}") from None
    elif resume:
        print(f"--resume: no lookahead checkpoint in {out.folder} ({LOOKAHEAD_CHECKPOINT}): "
              f"the lookahead starts from its first decision")
    return checkpoint


def close_checkpoint(checkpoint: Path):
    """Remove the checkpoint and its folder once the lookahead's tables are written (a
    leftover would refuse the next run into --out): a line says where that fails."""
    try:
        checkpoint.unlink(missing_ok=True)
        if checkpoint.parent.is_dir() and not any(checkpoint.parent.iterdir()):
            checkpoint.parent.rmdir()
    except OSError as error:
        print(f"could not remove the lookahead's checkpoint {checkpoint} "
              f"({error.strerror or error}): its tables are written; remove it before the next "
              f"run into this folder")


def read_primitive_model(path, period: float, dt: float,
                         base: Optional[StarParams] = None) -> PrimitiveModel:
    """The planner's model from a primitives CSV made at this period and step in every row,
    and where its provenance sidecar records the robot's parameters, for `base`'s (every field
    but the gait: a paper table drove the identified robot without a word, an audit);
    StudyArgumentError naming --primitives otherwise, or for a table the planner refuses
    (`PrimitiveModel.from_table`: a cell that is no number, a measured gait's that is not
    finite, gaits that are none or listed twice), all before the model is built. A sidecar that
    cannot be read or no longer describes the table (`read_provenance`: its SHA-256 differs,
    the table edited since) records no robot: the table is read as one without a sidecar, and
    a printed line says so."""
    table = cli.read_table(path, "--primitives", ["gait", "status", "period_s", "dt_s",
                                                  "step_x_mm", "step_y_mm", "turn_deg"],
                           "a primitives table")
    cli.numeric_columns(table, ["period_s", "dt_s"], path, "--primitives")
    made = table[["period_s", "dt_s"]].to_numpy()
    # every row's (only the first row's had been compared)
    elsewhere = ~np.isclose(made, (period, dt), rtol=1e-12, atol=0).all(axis=1)
    if elsewhere.any():
        row = table[elsewhere].iloc[0]
        raise cli.StudyArgumentError(f"--primitives {path}: made at period {row['period_s']} s, "
                                     f"dt {row['dt_s']} s (gait {row['gait']}); this run has "
                                     f"{period} s, {dt} s")
    if base is not None:
        recorded, differing = cli.robot_differences(path, base)
        if differing:
            own = provenance.plain(base)
            raise cli.StudyArgumentError(
                f"--primitives {path}: measured on a robot whose {differing[0]} is "
                f"{recorded[differing[0]]}, this run's {own[differing[0]]} ({len(differing)} "
                f"field(s) differ; its sidecar records them, a field it does not record at its "
                f"default): measure this robot's")
    try:
        return PrimitiveModel.from_table(table)
    except ValueError as error:
        raise cli.StudyArgumentError(f"--primitives {path}: "
                                     f"{str(error).removeprefix('table: ')}") from None


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if args.primitives is not None and args.measurement_flags:
        # they set the measurement a given table replaces: ignored, yet range-checked (an audit)
        raise cli.StudyArgumentError(f"{args.measurement_flags[0]}: not with --primitives (it "
                                     f"sets the primitives' measurement, which the table given "
                                     f"replaces)")
    for value, flag, lowest in ((args.max_cycles, "--max-cycles", 1),
                                (args.cycles, "--cycles", 2),
                                (args.glide_cycles, "--glide-cycles", 0),
                                (args.settle_cycles, "--settle-cycles", 0)):
        if value < lowest:
            raise cli.StudyArgumentError(f"{flag} must be >= {lowest}, got {value}")
    goals, base, solver, frames = cli.driving(args)
    lookahead_gaits = None
    if args.lookahead:
        lookahead_gaits = cli.resolve_gaits(
            args.lookahead_gaits or (QUICK_LOOKAHEAD_GAITS if args.quick else "all"),
            "--lookahead-gaits")
        try:
            check_lookahead(goals, base, solver, args.tolerance, args.max_cycles,
                            args.settle_cycles, lookahead_gaits, frames, args.arch)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--lookahead: {error}") from None
    elif args.lookahead_gaits is not None or args.resume:
        flag = "--lookahead-gaits" if args.lookahead_gaits is not None else "--resume"
        raise cli.StudyArgumentError(f"{flag}: only with --lookahead")
    if args.primitives is not None:
        model = read_primitive_model(args.primitives, base.period, solver.dt, base)
    else:  # the primitives' longest run, as that study checks it
        cli.check_cycles({"--cycles": args.cycles, "--glide-cycles": args.glide_cycles},
                         base.period, solver)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver,
                     extra={"tolerance_mm": args.tolerance, "max_cycles": args.max_cycles,
                            "settle_cycles": args.settle_cycles,
                            **({"lookahead_gaits": lookahead_gaits} if args.lookahead else {}),
                            "primitives": (str(Path(args.primitives).resolve())
                                           if args.primitives else "measured in this run"),
                            **({"primitives_sha256": hashlib.sha256(
                                Path(args.primitives).read_bytes()).hexdigest()}
                               if args.primitives else {})})
    if args.lookahead:
        checkpoint = open_checkpoint(out, args.resume, functools.partial(
            check_lookahead, goals, base, solver, args.tolerance, args.max_cycles,
            args.settle_cycles, lookahead_gaits, frames, args.arch))
    if args.primitives is None:
        primitives, _ = measure_primitives(base, solver, cycles=args.cycles,
                                           first_cycle=PRIMITIVES_FIRST_CYCLE, arch=args.arch,
                                           progress=not args.no_progress,
                                           glide_cycles=args.glide_cycles)
        out.write_csv(primitives, "primitives.csv")
        # --glide-cycles 0 plans without glides on purpose
        model = PrimitiveModel.from_table(primitives, expect_glides=args.glide_cycles > 0)
    summary, per_cycle, path = drive(model, goals, base, solver,
                                     tolerance_mm=args.tolerance, max_cycles=args.max_cycles,
                                     frames_per_cycle=frames, arch=args.arch,
                                     progress=not args.no_progress,
                                     settle_cycles=args.settle_cycles)
    gain = pd.DataFrame([closed_loop_gain(summary)])
    plan_csv = out.write_csv(summary, "plan.csv")
    out.write_csv(gain, "plan_gain.csv")
    out.write_csv(per_cycle, "plan_cycles.csv")
    paths_csv = out.write_csv(path, "plan_paths.csv")
    lookahead = None
    if args.lookahead:
        ahead, ahead_cycles, ahead_path = lookahead_drive(
            goals, base, solver, tolerance_mm=args.tolerance, max_cycles=args.max_cycles,
            settle_cycles=args.settle_cycles, gaits=lookahead_gaits, frames_per_cycle=frames,
            arch=args.arch, progress=not args.no_progress,
            checkpoint=out.path(LOOKAHEAD_CHECKPOINT))
        lookahead = (out.write_csv(ahead_path, "lookahead_paths.csv"),
                     out.write_csv(ahead, "lookahead.csv"))
        out.write_csv(ahead_cycles, "lookahead_cycles.csv")
        controllers = out.write_csv(compare_controllers(pd.concat([summary, ahead])),
                                    "controllers.csv")
        close_checkpoint(checkpoint)
    out.wrote(plot_paths(paths_csv, plan_csv, out.path("plan.png"), lookahead))
    out.report()
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(summary.to_string(index=False))
        print(gain.T.to_string(header=False))
        if args.lookahead:
            print(ahead.to_string(index=False))
            print(pd.read_csv(controllers).to_string(index=False))
    return summary
