"""Animation: a GIF of the robot's rod shape over one actuation cycle, per gait.

    python -m studies animate [--gait A1+A2 | --gait paper] [--cycles 1] [--frames 60]
                              [--preset paper|accurate] [--set NAME=VALUE] [--out DIR] [--quick]

All requested gaits run in one batch. Writes, under `<out>/animations/`: `shapes.csv` (gait,
frame, t_s, node, x_mm, y_mm: every node at every frame), `centroid.csv` (gait, frame, t_s,
x_mm, y_mm: centroid relative to its start), `edges.csv` (the topology: node_a, node_b, kind,
actuator) and `<gait>.gif` drawn from those CSVs: limbs brown, resting actuators gray, fired
actuators red, the central cylinder, and beside it the centroid path (zoomed).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.batch import run_batch
from taichi_star.gait import Gait

from . import cli

DESCRIPTION = "GIF of the robot's rod shape over one actuation cycle, for one or more gaits."


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


def draw_gif(shapes_csv, centroid_csv, edges_csv, gait: str, gif_path, fps: int = 15):
    """Render one gait's GIF from the three CSVs."""
    plt = cli.use_agg()
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle

    shapes = pd.read_csv(shapes_csv)
    shapes = shapes[shapes["gait"] == gait]
    centroid = pd.read_csv(centroid_csv)
    centroid = centroid[centroid["gait"] == gait].sort_values("frame")
    edges = pd.read_csv(edges_csv)
    fired = set(Gait.parse(gait).actuators)
    colours, widths = [], []
    for _, edge in edges.iterrows():
        if edge["kind"] == "spoke":
            colours.append("0.85"), widths.append(0.8)
        elif edge["kind"] == "limb":
            colours.append("saddlebrown"), widths.append(2.5)
        else:
            active = int(edge["actuator"]) in fired
            colours.append("red" if active else "0.45"), widths.append(2.2 if active else 1.6)
    a, b = edges["node_a"].to_numpy(), edges["node_b"].to_numpy()
    frames = sorted(shapes["frame"].unique())
    positions = {f: part.sort_values("node")[["x_mm", "y_mm"]].to_numpy()
                 for f, part in shapes.groupby("frame")}
    times = shapes.groupby("frame")["t_s"].first()

    # the centroid path in a panel of its own: inside the robot's axes it covered the A2 label
    fig, (ax, inset) = plt.subplots(1, 2, figsize=(7, 5), gridspec_kw={"width_ratios": [3, 1.2]},
                                    layout="constrained")
    ax.set_aspect("equal")
    low = np.minimum(shapes[["x_mm", "y_mm"]].min().to_numpy(), -60.0)
    high = np.maximum(shapes[["x_mm", "y_mm"]].max().to_numpy(), 60.0)
    centre, half = 0.5 * (low + high), 0.5 * float((high - low).max()) + 6.0
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_xlabel("x (mm)")
    ax.set_ylabel("y (mm)")
    lines = LineCollection([], colors=colours, linewidths=widths)
    ax.add_collection(lines)
    cylinder = Circle((0, 0), 15.0, facecolor="lightsteelblue", edgecolor="k", lw=0.6, zorder=0)
    ax.add_patch(cylinder)
    for m in range(1, 9):
        angle = math.radians(45.0 * (m - 1))
        ax.text(60 * math.cos(angle), 60 * math.sin(angle), f"A{m}", ha="center", va="center",
                fontsize=7, color="red" if m in fired else "0.4")
    cx, cy = centroid["x_mm"].to_numpy(), centroid["y_mm"].to_numpy()
    span = max(float(np.nanmax(np.abs(np.r_[cx, cy]))) if len(cx) else 0.0, 0.05) * 1.2
    inset.set_xlim(-span, span)
    inset.set_ylim(-span, span)
    inset.set_aspect("equal")
    inset.tick_params(labelsize=7)
    inset.set_title("centroid path (mm)", fontsize=9)
    path_line, = inset.plot([], [], "b-", lw=0.8)
    dot, = inset.plot([], [], "bo", ms=3)
    title = ax.set_title("")

    def update(i):
        frame = frames[i]
        xy = positions[frame]
        lines.set_segments(np.stack([xy[a], xy[b]], axis=1))
        cylinder.center = tuple(xy[0])
        path_line.set_data(cx[:i + 1], cy[:i + 1])
        dot.set_data(cx[i:i + 1], cy[i:i + 1])
        title.set_text(f"{gait}   t = {times[frame]:.2f} s")
        return lines, cylinder, path_line, dot, title

    animation = FuncAnimation(fig, update, frames=len(frames), blit=False)
    animation.save(gif_path, writer=PillowWriter(fps=fps), dpi=100)
    plt.close(fig)
    return Path(gif_path)


def build_parser():
    parser = cli.StudyParser("animate", DESCRIPTION)
    parser.add_argument("--gait", default="paper", quick="A1+A2",
                        help="gait(s): A1+A2, a comma list, or paper (the five Fig. 4 gaits)")
    parser.add_argument("--frames", type=int, default=60, help="frames per GIF (about; default 60)")
    parser.add_argument("--fps", type=int, default=15, help="GIF frame rate (default 15)")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser, default=1.0)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if args.frames < 2:
        raise cli.StudyArgumentError(f"--frames must be >= 2, got {args.frames}")
    if args.fps < 1:
        raise cli.StudyArgumentError(f"--fps must be >= 1, got {args.fps}")
    gaits = cli.resolve_gaits(args.gait, "--gait")
    base = cli.base_params(args)
    params = [base.replace(gait=g) for g in gaits]
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    duration = cli.duration_s(args, base.period)
    stride = max(1, int(round(duration / solver.dt)) // args.frames)
    result = run_batch(params, duration, solver=solver, arch=args.arch,
                       record_interval_s=stride * solver.dt, record_shapes=True,
                       progress=not args.no_progress)
    times = sorted(result.trajectory[result.trajectory["instance"] == 0]["t_s"])
    shapes = shapes_table(gaits, [result.shapes[:, i] for i in range(len(gaits))], times)
    centroid = result.trajectory.copy()
    centroid["frame"] = centroid.groupby("instance").cumcount()
    centroid["gait"] = [gaits[i] for i in centroid["instance"]]
    tables = [out.write_csv(shapes, "animations/shapes.csv"),
              out.write_csv(centroid[["gait", "frame", "t_s", "x_mm", "y_mm"]],
                            "animations/centroid.csv"),
              out.write_csv(edges_table(result.topology), "animations/edges.csv")]
    for gait, status in zip(gaits, result.summary["status"]):
        gif = out.path(f"animations/{gait.replace('+', '_')}.gif")
        out.wrote(draw_gif(*tables, gait, gif, fps=args.fps))
        if status != "ok":
            print(f"  warning: {gait} ended with status {status}")
    out.report()
    return out.written
