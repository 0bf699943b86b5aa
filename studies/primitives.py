"""Motion primitives: every gait's steady per-cycle step in the body frame and its turn per
cycle, from one batch of the 29 symmetry-class representatives expanded to the 255 gaits.

    python -m studies primitives [--cycles 5] [--first-cycle 1] [--set NAME=VALUE ...]
                                 [--discretisation paper|converged] [--dt S] [--arch cpu|gpu]
                                 [--out DIR] [--quick]

Writes into --out (default a fresh runs/primitives/<timestamp>/), each CSV with a JSON sidecar
(command line, version):
- `primitives.csv`: one row per gait (`taichi_star.primitives.PRIMITIVE_COLUMNS`): mean step
  (mm per cycle, body frame) and its spread, length and direction, mean turn per cycle and its
  spread, over cycles first_cycle..cycles-1 (0-based; default 1..4, i.e. cycles 2-5);
- `primitives_cycles.csv`: every gait's per-cycle steps and turns;
- `primitives.png`: the primitives in polar form (direction, step length), coloured by turn,
  drawn from primitives.csv.

--quick: 2 cycles at dt = 5 ms (statistics over cycle 2 alone; spreads NaN).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.params import SolverConfig
from taichi_star.primitives import measure_primitives

from . import common

DESCRIPTION = ("Every gait's steady per-cycle step (body frame) and turn, from one batch of "
               "the 29 symmetry classes expanded to 255 gaits; CSV and a polar plot.")
QUICK_CYCLES = 2
QUICK_DT = 5e-3


def plot_primitives(csv_path, png_path):
    """Polar plot from a primitives CSV: each gait at (direction, step length) in the body
    frame (A1's bisector at 0°), coloured by its turn per cycle; the fastest class labelled."""
    plt = common.use_agg()
    table = pd.read_csv(csv_path)
    moving = table[np.isfinite(table["direction_deg"])]
    fig = plt.figure(figsize=(7.2, 6.4))
    ax = fig.add_subplot(projection="polar")
    limit = max(float(np.nanmax(np.abs(moving["turn_deg"]))), 1e-6)
    points = ax.scatter(np.radians(moving["direction_deg"]), moving["step_mm"],
                        c=moving["turn_deg"], cmap="coolwarm", vmin=-limit, vmax=limit,
                        s=8 + 6 * moving["n_actuators"], edgecolors="k", linewidths=0.3)
    fastest = moving.loc[moving["step_mm"].idxmax()]
    ax.annotate(fastest["gait"].replace("+", "&"),
                (np.radians(fastest["direction_deg"]), fastest["step_mm"]), fontsize=7,
                xytext=(4, 4), textcoords="offset points")
    fig.colorbar(points, ax=ax, pad=0.1, shrink=0.8, label="turn per cycle (deg, ccw)")
    period = table["period_s"].iloc[0]
    cycles = f"{int(table['first_cycle'].iloc[0]) + 1}-{int(table['cycles'].iloc[0])}"
    ax.set_title(f"Motion primitives: step per cycle (mm, body frame) of the {len(table)} "
                 f"gaits\nT = {period:g} s, mean over cycles {cycles}; marker size = actuators",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def build_parser():
    parser = common.common_parser("primitives", DESCRIPTION)
    parser.set_defaults(out=None)
    parser.add_argument("--cycles", type=int, default=None,
                        help=f"cycles from rest (default 5; --quick {QUICK_CYCLES})")
    parser.add_argument("--first-cycle", type=int, default=1,
                        help="first cycle (0-based) of the statistics (default 1: cycles 2..)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override one StarParams field, e.g. --set alpha=1.0")
    return parser


def main(argv=None):
    argv = list(argv or [])
    args = build_parser().parse_args(argv)
    cycles = args.cycles if args.cycles is not None else (QUICK_CYCLES if args.quick else 5)
    if cycles < 1 or not 0 <= args.first_cycle < cycles:
        raise common.StudyArgumentError(f"--first-cycle must be in [0, --cycles - 1] with "
                                        f"--cycles >= 1, got {args.first_cycle} and {cycles}")
    overrides = common.parse_overrides(args.set)
    if "gait" in overrides:
        raise common.StudyArgumentError("--set gait=...: the study runs every gait")
    try:
        base = common.base_params(args).replace(**overrides)
        solver = SolverConfig(dt=args.dt if args.dt is not None else
                              (QUICK_DT if args.quick else 1e-3))
    except (ValueError, TypeError) as error:
        raise common.StudyArgumentError(f"invalid parameter value: {error}") from None
    out = common.fresh_output(args, "primitives")
    try:
        table, per_cycle = measure_primitives(base, solver, cycles=cycles,
                                              first_cycle=args.first_cycle, arch=args.arch,
                                              progress=not args.no_progress)
    except ValueError as error:
        raise common.StudyArgumentError(str(error)) from None
    details = {"overrides": overrides, "discretisation": args.discretisation}
    paths = [common.write_table(table, out / "primitives.csv", "primitives", argv, details),
             common.write_table(per_cycle, out / "primitives_cycles.csv", "primitives", argv,
                                details)]
    paths.append(plot_primitives(paths[0], out / "primitives.png"))
    print(common.describe(paths))
    best = table.sort_values("step_mm", ascending=False).drop_duplicates("class_representative")
    print(best[["class_representative", "step_mm", "step_x_std_mm", "turn_deg"]]
          .head(5).to_string(index=False))
    return table
