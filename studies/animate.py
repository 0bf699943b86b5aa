"""Animation: a GIF of the robot's rod shape over one actuation cycle, per gait.

    python -m studies animate [--gait A1+A2 | --gait paper] [--cycles 1] [--frames 60]
                              [--preset paper|accurate] [--set NAME=VALUE] [--out DIR] [--quick]

All requested gaits run in one batch. Writes, under `<out>/animations/`: `shapes.csv` (gait,
frame, t_s, node, x_mm, y_mm: every node at every frame), `centroid.csv` (gait, frame, t_s,
x_mm, y_mm: centroid relative to its start; both `taichi_star.output.animation_tables`),
`edges.csv` (the topology: node_a, node_b, kind, actuator; `taichi_star.output.edge_table`)
and `<gait>.gif`, drawn from shapes.csv and centroid.csv as written (read back and replayed
into the run's result, `taichi_star.output.replay`) by the library's animator
(`SimulationResult.animate`): limbs brown, actuators gray and red while they heat, labels
A1..A8, the central cylinder, a scale bar and the centroid's path.
"""

from __future__ import annotations

import pandas as pd

from taichi_star.batch import run_batch
from taichi_star.output import GIF_MOST_FPS, animation_tables, edge_table, replay
from taichi_star.runtime import MemoryBudgetError
from taichi_star.timegrid import interval_for_count

from . import cli

DESCRIPTION = "GIF of the robot's rod shape over one actuation cycle, for one or more gaits."


MAX_FRAMES = 10_000
"""The most frames of one movie: almost three minutes at 60 frames per second (each frame is a
recorded shape and a drawn picture; a billion ran out of memory, an audit)."""


def build_parser():
    parser = cli.StudyParser("animate", DESCRIPTION)
    parser.add_argument("--gait", default="paper", quick="A1+A2",
                        help=cli.GAITS_HELP)
    parser.add_argument("--frames", type=int, default=60,
                        help="frames per GIF (default 60): at least this many where the run has "
                             "as many steps, fewer than twice as many")
    parser.add_argument("--fps", type=int, default=15,
                        help=f"GIF frame rate, 1 to {GIF_MOST_FPS} (default 15)")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser, default=1.0)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if not 2 <= args.frames <= MAX_FRAMES:
        raise cli.StudyArgumentError(f"--frames must be in [2, {MAX_FRAMES}], got {args.frames}")
    cli.check_count(args.fps, "--fps", 1, GIF_MOST_FPS)  # a GIF's frame delays: the library's
    gaits = cli.resolve_gaits(args.gait, "--gait")
    base = cli.base_params(args)
    params = [base.replace(gait=g) for g in gaits]
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    duration = cli.duration_s(args, base.period)
    try:
        result = run_batch(params, duration, solver=solver, arch=args.arch,
                           record_interval_s=interval_for_count(duration, args.frames,
                                                                solver.dt),
                           record_shapes=True, progress=not args.no_progress)
    except MemoryBudgetError as error:  # refused before any compute: the frames are the flag
        raise cli.StudyArgumentError(f"--frames {args.frames} of {len(gaits)} gait(s) over "
                                     f"{duration:g} s: {error}") from None
    shapes, centroid = animation_tables(result, gaits)
    shapes_csv = out.write_csv(shapes, "animations/shapes.csv")
    centroid_csv = out.write_csv(centroid, "animations/centroid.csv")
    out.write_csv(edge_table(base), "animations/edges.csv")
    drawn = replay(result, pd.read_csv(shapes_csv), pd.read_csv(centroid_csv))
    for instance, (gait, status) in enumerate(zip(gaits, result.summary["status"])):
        gif = out.path(f"animations/{gait.replace('+', '_')}.gif")
        out.wrote(drawn.animate(gif, instances=[instance], fps=args.fps, size_px=600,
                                title=f"gait {gait}"))
        if status != "ok":
            print(f"  warning: {gait} ended with status {status}")
    out.report()
    return out.written
