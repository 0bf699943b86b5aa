"""Animation: a GIF of the robot's rod shape over one actuation cycle, per gait.

    python -m studies animate [--gait A1+A2 | --gait paper] [--cycles 1] [--frames 90]
                              [--arch cpu|gpu] [--out results/] [--quick]

All requested gaits run in one batch. Writes, under `<out>/animations/`: `shapes.csv` (gait,
frame, t_s, node, x_mm, y_mm: every node at every frame), `centroid.csv` (gait, frame, t_s,
x_mm, y_mm: centroid relative to its start), `edges.csv` (the topology: node_a, node_b, kind,
actuator) and `<gait>.gif` drawn from those CSVs: limbs brown, resting actuators gray, fired
actuators red, the central cylinder, and the centroid path in a zoomed inset.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.gait import Gait
from taichi_star.geometry import ARC, LIMB, SPOKE

from . import common

DESCRIPTION = "GIF of the robot's rod shape over one actuation cycle, for one or more gaits."

KIND_NAMES = {SPOKE: "spoke", LIMB: "limb", ARC: "arc"}


def edges_table(topology) -> pd.DataFrame:
    """The batch topology's edges: node_a, node_b, kind (spoke/limb/arc), actuator (1..8 for arc
    edges, 0 otherwise), from the node numbering of `geometry.build_topology`."""
    block = (topology.n_nodes - 1) // 8
    kinds = [KIND_NAMES[int(k)] for k in topology.edge_kind]
    actuator = [int((a - 1) // block) + 1 if k == ARC else 0
                for (a, _), k in zip(topology.edges, topology.edge_kind)]
    return pd.DataFrame({"node_a": topology.edges[:, 0], "node_b": topology.edges[:, 1],
                         "kind": kinds, "actuator": actuator})


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
    plt = common.use_agg()
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

    fig, ax = plt.subplots(figsize=(5, 5))
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
    inset = ax.inset_axes([0.70, 0.70, 0.28, 0.28])
    cx, cy = centroid["x_mm"].to_numpy(), centroid["y_mm"].to_numpy()
    span = max(float(np.nanmax(np.abs(np.r_[cx, cy]))) if len(cx) else 0.0, 0.05) * 1.2
    inset.set_xlim(-span, span)
    inset.set_ylim(-span, span)
    inset.set_aspect("equal")
    inset.tick_params(labelsize=5)
    inset.set_title("centroid (mm)", fontsize=6)
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
    animation.save(gif_path, writer=PillowWriter(fps=fps), dpi=80)
    plt.close(fig)
    return Path(gif_path)


def build_parser():
    parser = common.common_parser("animate", DESCRIPTION)
    parser.add_argument("--gait", default=None,
                        help="gait(s): A1+A2, a comma list, or paper (the five Fig. 4 gaits; "
                             "default; A1+A2 with --quick)")
    parser.add_argument("--cycles", type=float, default=1.0, help="cycles to show (default 1)")
    parser.add_argument("--frames", type=int, default=60, help="frames per GIF (about; default 60)")
    parser.add_argument("--fps", type=int, default=15, help="GIF frame rate (default 15)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override a StarParams field, e.g. --set alpha=1.0")
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    common.check_positive(args.cycles, "--cycles")
    if args.frames < 2:
        raise common.StudyArgumentError(f"--frames must be >= 2, got {args.frames}")
    if args.fps < 1:
        raise common.StudyArgumentError(f"--fps must be >= 1, got {args.fps}")
    gaits = common.resolve_gaits(args.gait or ("A1+A2" if args.quick else "paper"), "--gait")
    overrides = common.parse_overrides(args.set)
    if "gait" in overrides:
        raise common.StudyArgumentError("--set gait=...: use --gait")
    try:
        base = common.base_params(args).replace(**overrides)
    except (ValueError, TypeError) as error:
        raise common.StudyArgumentError(f"--set: {error}") from None
    params = [base.replace(gait=g) for g in gaits]
    solver = common.solver_for(args)
    duration = common.QUICK_DURATION_S if args.quick else args.cycles * base.period
    steps = int(round(duration / solver.dt))
    stride = max(1, steps // args.frames)
    out = common.out_dir(args) / "animations"
    out.mkdir(parents=True, exist_ok=True)
    result = common.run_batch(params, duration_s=duration, solver=solver, arch=args.arch,
                              record_every=stride, record_shapes=True,
                              progress=not args.no_progress)
    topology = result.topologies[0]
    times = sorted(result.trajectory[result.trajectory["instance"] == 0]["t_s"])
    shapes = shapes_table(gaits, [result.shapes[i] for i in range(len(gaits))], times)
    centroid = result.trajectory.copy()
    centroid["frame"] = centroid.groupby("instance").cumcount()
    centroid["gait"] = [gaits[i] for i in centroid["instance"]]
    paths = [common.write_csv(shapes, out / "shapes.csv"),
             common.write_csv(centroid[["gait", "frame", "t_s", "x_mm", "y_mm"]],
                              out / "centroid.csv"),
             common.write_csv(edges_table(topology), out / "edges.csv")]
    for gait, status in zip(gaits, result.summary["status"]):
        gif = out / f"{gait.replace('+', '_')}.gif"
        paths.append(draw_gif(paths[0], paths[1], paths[2], gait, gif, fps=args.fps))
        if status != "ok":
            print(f"  warning: {gait} ended with status {status}")
    print(common.describe(paths))
    return paths
