"""Fig. 4c and 4b of the paper: the five gaits at the paper's parameters, 3 cycles from rest.

    python -m studies fig4c [--out DIR] [--quick] [--arch cpu|gpu] [--preset paper|accurate]
                            [--set NAME=VALUE ...] [--cycles 3] [--dt S] [--prefix fig4c]

Writes (prefix `fig4c` by default), each table with its provenance sidecar (`.csv.json`):
- `fig4c.csv`: gait, sim_speed_mm_s, sim_signed_speed_mm_s, sim_direction, exp_speed_mm_s,
  exp_cycle_speed_std_mm_s, paper_direction, direction_matches, speed_ratio, status
  (experiment: full-trial speeds, and the spread of its per-cycle speeds, drawn as error bars);
- `fig4c_summary.csv`: the full simulation summary (every parameter, whole-run and steady
  speeds, Newton statistics, status);
- `fig4b.csv`: centroid displacement against time, simulation and experiment (long form);
- `fig4c.png` (grouped bars, simulation next to experiment) and `fig4b.png` (displacement
  against time, simulation solid, experiment dashed), drawn from the CSVs above.
"""

from __future__ import annotations

import pandas as pd

from . import cli, figures

DESCRIPTION = ("The paper's Fig. 4c/4b: speed of the five gaits (A1, A1+A2, A1+A3, A1+A4, "
               "A1+A3+A5), simulation vs experiment, 3 cycles from rest.")


def build_parser():
    parser = cli.StudyParser("fig4c", DESCRIPTION)
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    parser.add_argument("--prefix", default="fig4c", help="output file prefix (default fig4c)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    base = cli.base_params(args)
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    table = figures.run_fig4c(out, base, solver, duration_s=cli.duration_s(args, base.period),
                              arch=args.arch, prefix=args.prefix, progress=not args.no_progress)
    out.report()
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(table.to_string(index=False))
    if args.quick:  # its ratios compare 0.2 s from rest with whole trials (an audit, 2026-12)
        print(f"--quick: {cli.duration_s(args, base.period):g} s from rest, a smoke test: its "
              f"speeds and ratios are not comparable with the experiment's whole trials")
    return table
