"""Motion primitives: every gait's steady per-cycle step in the body frame and its turn per
cycle, from one batch of the 29 symmetry-class representatives expanded to the 255 gaits (a
robot whose actuators differ, e.g. --preset identified: one batch of all 255 gaits).

    python -m studies primitives [--cycles 5] [--first-cycle 1] [--glide-cycles 4]
                                 [--preset paper|accurate|identified] [--set NAME=VALUE ...]
                                 [--dt S] [--arch cpu|gpu] [--out DIR] [--quick]

Writes into --out (default a fresh runs/primitives/<timestamp>/), each CSV with its provenance
sidecar (`.csv.json`):
- `primitives.csv`: one row per gait (`taichi_star.primitives.PRIMITIVE_COLUMNS`): mean step
  (mm per cycle, body frame) and its spread, length and direction, mean turn per cycle and its
  spread, over cycles first_cycle..cycles-1 (0-based; default 1..4, i.e. cycles 2-5); the
  step of each cycle k from rest (step{k}_x/y_mm); and, with --glide-cycles > 0, the glide
  after k = 1..--cycles firings in a row (`taichi_star.primitives.measure_glides`: k firings
  from rest, then --glide-cycles cycles of coasting; glide{k}_x/y_mm in the body frame), which
  the planner plans with;
- `primitives_cycles.csv`: every gait's per-cycle steps and turns;
- `primitives.png`: the primitives in polar form (direction, step length), coloured by turn,
  drawn from primitives.csv.

--quick: 2 cycles at dt = 5 ms (statistics over cycle 2 alone; spreads NaN), a glide of one
cycle.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.primitives import GLIDE_CYCLES, check_measurement, measure_primitives

from . import cli

DESCRIPTION = ("Every gait's steady per-cycle step (body frame) and turn, from one batch of "
               "the 29 symmetry classes expanded to 255 gaits (of all 255 gaits when the "
               "actuators differ); CSV and a polar plot.")
QUICK_CYCLES = 2
QUICK_DT = 5e-3
QUICK_GLIDE_CYCLES = 1


def plot_primitives(csv_path, png_path) -> Path:
    """Polar plot from a primitives CSV: each gait at (direction, step length) in the body
    frame (A1's bisector at 0°), coloured by its turn per cycle; the fastest class labelled."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    moving = table[np.isfinite(table["direction_deg"])]
    fig = plt.figure(figsize=(7.2, 6.4))
    ax = fig.add_subplot(projection="polar")
    limit = max(float(np.nanmax(np.abs(moving["turn_deg"]))), 1e-6)
    points = ax.scatter(np.radians(moving["direction_deg"]), moving["step_mm"],
                        c=moving["turn_deg"], cmap="coolwarm", vmin=-limit, vmax=limit,
                        s=8 + 6 * moving["n_actuators"], edgecolors="k", linewidths=0.3)
    fastest = moving.loc[moving["step_mm"].idxmax()]
    ax.annotate(fastest["gait"],
                (np.radians(fastest["direction_deg"]), fastest["step_mm"]), fontsize=7,
                xytext=(4, 4), textcoords="offset points")
    fig.colorbar(points, ax=ax, pad=0.1, shrink=0.8, label="turn per cycle (deg, ccw)")
    period = table["period_s"].iloc[0]
    cycles = f"{int(table['first_cycle'].iloc[0]) + 1}-{int(table['cycles'].iloc[0])}"
    ax.set_title(f"Motion primitives: step per cycle (mm, body frame) of the {len(table)} "
                 f"gaits\nT = {period:g} s, mean over cycles {cycles}; marker size = actuators",
                 fontsize=9)
    return cli.save_figure(fig, png_path)


def build_parser():
    parser = cli.StudyParser("primitives", DESCRIPTION)
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser, quick=QUICK_DT)
    parser.add_argument("--cycles", type=int, default=5, quick=QUICK_CYCLES,
                        help="actuation cycles from rest")
    parser.add_argument("--first-cycle", type=int, default=1,
                        help="first cycle (0-based) of the statistics (default 1: cycles 2..)")
    parser.add_argument("--glide-cycles", type=int, default=GLIDE_CYCLES,
                        quick=QUICK_GLIDE_CYCLES,
                        help="cycles of coasting over which each gait's glide after its last "
                             "firing is measured (0: none)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if args.glide_cycles < 0:
        raise cli.StudyArgumentError(f"--glide-cycles must be >= 0, got {args.glide_cycles}")
    if not 0 <= args.first_cycle < args.cycles:
        raise cli.StudyArgumentError(f"--first-cycle must be in [0, --cycles - 1 = "
                                     f"{args.cycles - 1}], got {args.first_cycle}")
    base = cli.base_params(args)
    solver = cli.solver(args)
    try:
        check_measurement(base, solver, args.cycles, args.first_cycle)
    except ValueError as error:
        raise cli.StudyArgumentError(f"--dt, --set period: {error}") from None
    # the longest run: the glide run fires --cycles in a row, then coasts --glide-cycles
    cli.check_cycles({"--cycles": args.cycles, "--glide-cycles": args.glide_cycles},
                     base.period, solver)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"cycles": args.cycles,
                                           "first_cycle": args.first_cycle,
                                           "glide_cycles": args.glide_cycles})
    table, per_cycle = measure_primitives(base, solver, cycles=args.cycles,
                                          first_cycle=args.first_cycle, arch=args.arch,
                                          progress=not args.no_progress,
                                          glide_cycles=args.glide_cycles)
    csv = out.write_csv(table, "primitives.csv")
    out.write_csv(per_cycle, "primitives_cycles.csv")
    out.wrote(plot_primitives(csv, out.path("primitives.png")))
    out.report()
    best = table.sort_values("step_mm", ascending=False).drop_duplicates("class_representative")
    print(best[["class_representative", "step_mm", "step_x_std_mm", "turn_deg"]]
          .head(5).to_string(index=False))
    return table
