"""Animation: a GIF of the robot's rod shape over one actuation cycle, per gait.

    python -m studies animate [--gait A1+A2 | --gait paper] [--cycles 1] [--frames 60]
                              [--preset paper|accurate] [--set NAME=VALUE] [--out DIR] [--quick]

All requested gaits run in one batch. Writes, under `<out>/animations/`: `shapes.csv` (gait,
frame, t_s, node, x_mm, y_mm: every node at every frame), `centroid.csv` (gait, frame, t_s,
x_mm, y_mm: centroid relative to its start), `edges.csv` (the topology: node_a, node_b, kind,
actuator) and `<gait>.gif`, drawn by the library's animator (`SimulationResult.animate`): limbs
brown, actuators gray and red while they heat, labels A1..A8, the central cylinder, a scale bar
and the centroid's path.
"""

from __future__ import annotations


import numpy as np
import pandas as pd

from taichi_star.batch import run_batch
from taichi_star.output import GIF_MOST_FPS
from taichi_star.timegrid import interval_for_count

from . import cli

DESCRIPTION = "GIF of the robot's rod shape over one actuation cycle, for one or more gaits."


MAX_FRAMES = 10_000
"""The most frames of one movie: almost three minutes at 60 frames per second (each frame is a
recorded shape and a drawn picture; a billion ran out of memory, an audit)."""


def edges_table(topology) -> pd.DataFrame:
    """The robot's edges from its limb and arc node chains: node_a, node_b, kind (spoke from the
    hub to a joint, limb, arc), actuator (1..8 for arc edges, 0 otherwise)."""
    chained = set(topology.limbs.ravel()) | set(topology.arcs.ravel())
    hub = next(n for n in range(topology.n_nodes) if n not in chained)
    rows = []
    for number, (limb, arc) in enumerate(zip(topology.limbs, topology.arcs), start=1):
        rows.append((hub, limb[0], "spoke", 0))
        rows += [(a, b, "limb", 0) for a, b in zip(limb[:-1], limb[1:])]
        rows += [(a, b, "arc", number) for a, b in zip(arc[:-1], arc[1:])]
    return pd.DataFrame(rows, columns=["node_a", "node_b", "kind", "actuator"])


def shapes_table(gaits, shapes, times) -> pd.DataFrame:
    """Long table of node positions (mm) from per-gait arrays (n_frames, N, 2) in m."""
    parts = []
    for gait, shape in zip(gaits, shapes):
        frames, nodes = shape.shape[0], shape.shape[1]
        parts.append(pd.DataFrame({
            "gait": gait,
            "frame": np.repeat(np.arange(frames), nodes),
            "t_s": np.repeat(np.asarray(times)[:frames], nodes),
            "node": np.tile(np.arange(nodes), frames),
            "x_mm": np.round(1e3 * shape[..., 0].ravel(), 5),
            "y_mm": np.round(1e3 * shape[..., 1].ravel(), 5)}))
    return pd.concat(parts, ignore_index=True)


def build_parser():
    parser = cli.StudyParser("animate", DESCRIPTION)
    parser.add_argument("--gait", default="paper", quick="A1+A2",
                        help="gait(s): A1+A2, a comma list, or paper (the five Fig. 4 gaits)")
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
    result = run_batch(params, duration, solver=solver, arch=args.arch,
                       record_interval_s=interval_for_count(duration, args.frames, solver.dt),
                       record_shapes=True,
                       progress=not args.no_progress)
    times = sorted(result.trajectory[result.trajectory["instance"] == 0]["t_s"])
    shapes = shapes_table(gaits, [result.shapes[:, i] for i in range(len(gaits))], times)
    centroid = result.trajectory.copy()
    centroid["frame"] = centroid.groupby("instance").cumcount()
    centroid["gait"] = [gaits[i] for i in centroid["instance"]]
    out.write_csv(shapes, "animations/shapes.csv")
    out.write_csv(centroid[["gait", "frame", "t_s", "x_mm", "y_mm"]], "animations/centroid.csv")
    out.write_csv(edges_table(result.topology), "animations/edges.csv")
    for instance, (gait, status) in enumerate(zip(gaits, result.summary["status"])):
        gif = out.path(f"animations/{gait.replace('+', '_')}.gif")
        out.wrote(result.animate(gif, instances=[instance], fps=args.fps, size_px=600,
                                 title=f"gait {gait}"))
        if status != "ok":
            print(f"  warning: {gait} ended with status {status}")
    out.report()
    return out.written
