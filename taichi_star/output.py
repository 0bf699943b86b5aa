"""Labelled data and video of a SimulationResult: an xarray Dataset (netCDF) and an animation
of the recorded shapes (MP4 through imageio-ffmpeg, or GIF)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional, Sequence

import numpy as np
import pandas as pd

from .extras import require
from .geometry import CENTRE
from .params import PARAMETER_UNITS, StarParams, parameter_column

UNITS = {"_per_wall_s": "1/s", "_per_s": "1/s", "_gb_s": "GB/s", "_mm_s": "mm/s", "_mm": "mm",
         "_deg": "degree", "_ms": "ms", "_us": "us", "_s": "s", "_m": "m"}
"""Units of result columns by name suffix, the first match counting (longer suffixes first)."""
PARAMETER_COLUMN_UNITS = {parameter_column(name): unit for name, unit in PARAMETER_UNITS.items()}
"""Units of the numeric parameter columns (youngs_modulus_pa: Pa, alpha: 1)."""


def column_unit(name: str) -> str:
    """The unit of a result column, from the parameter columns or its suffix ("" if none)."""
    if name in PARAMETER_COLUMN_UNITS:
        return PARAMETER_COLUMN_UNITS[name]
    for suffix, unit in UNITS.items():
        if name.endswith(suffix):
            return unit
    return ""


def column_units(columns) -> dict:
    """{column: unit} for the columns whose unit the name tells (see `column_unit`)."""
    return {name: column_unit(name) for name in columns if column_unit(name)}


def to_xarray(result):
    """The result as an xarray Dataset: per instance (dim `instance`) every summary column, the
    parameters as coordinates; per record (dims `instance`, `time`) the centroid and heading;
    with recorded shapes, `positions` (time, instance, node, xy) in m. Every variable carries a
    `units` attribute."""
    xr = require("xarray", "io")

    summary = result.summary.reset_index(drop=True)
    parameter_columns = set(StarParams.columns().values())
    instances = np.arange(len(summary))
    coordinates = {"instance": instances}
    variables = {}
    for name in summary.columns.drop("actuator_profile"):
        values = summary[name].to_numpy()
        if values.dtype == object or pd.api.types.is_string_dtype(summary[name]):
            values = summary[name].astype(str).to_numpy()
        into = coordinates if name in parameter_columns else variables
        into[name] = ("instance", values, {"units": column_unit(name)})
    trajectory = result.trajectory
    if len(trajectory):
        times = np.sort(trajectory["t_s"].unique())
        coordinates["time"] = ("time", times, {"units": "s"})
        table = trajectory.pivot(index="instance", columns="t_s")
        for name in ("x_mm", "y_mm", "heading_deg"):
            variables[f"centroid_{name}" if name != "heading_deg" else "record_heading_deg"] = (
                ("instance", "time"), table[name].reindex(columns=times).to_numpy(),
                {"units": column_unit(name)})
    if result.shapes is not None:
        coordinates["node"] = np.arange(result.shapes.shape[2])
        coordinates["xy"] = ["x", "y"]
        variables["positions"] = (("time", "instance", "node", "xy"), result.shapes, {"units": "m"})
    dataset = xr.Dataset(variables, coords=coordinates)
    dataset.attrs.update({"integrator": result.solver.integrator, "dt_s": result.solver.dt,
                          "adaptive": int(result.solver.adaptive),
                          "precision": result.solver.precision})
    return dataset


def animate(result, path, instances: Optional[Sequence[int]] = None, frame: str = "world",
            fps: int = 15, size_px: int = 720):
    """Write the recorded shapes of some instances (default: all, up to 16) as an animation:
    MP4 (through imageio-ffmpeg's ffmpeg) for a `.mp4` path, GIF for `.gif`. `frame` "world"
    (lab axes, the centroid's path drawn) or "body" (following the centroid and the body's
    rotation). Returns the path. Raises ValueError without recorded shapes, for an unknown
    frame or suffix, or for instances out of range."""
    matplotlib = require("matplotlib", "video")
    require("PIL", "video")

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation

    path = Path(path)
    if result.shapes is None or result.topology is None:
        raise ValueError("animate needs recorded shapes of one topology: simulate with "
                         "record_interval_s > 0 and record_shapes=True")
    if frame not in ("world", "body"):
        raise ValueError(f"frame must be 'world' or 'body', got {frame!r}")
    if path.suffix.lower() not in (".mp4", ".gif"):
        raise ValueError(f"path must end in .mp4 or .gif, got {path.name!r}")
    batch = result.shapes.shape[1]
    chosen = list(range(min(batch, 16))) if instances is None else [int(i) for i in instances]
    if not chosen or min(chosen) < 0 or max(chosen) >= batch:
        raise ValueError(f"instances must be in [0, {batch}), got {instances!r}")
    times = np.sort(result.trajectory["t_s"].unique())
    shapes = result.shapes[:, chosen] * 1e3  # mm
    if frame == "body":
        shapes = _body_frame(shapes, result.topology)
    columns = int(np.ceil(np.sqrt(len(chosen))))
    rows = int(np.ceil(len(chosen) / columns))
    inches = size_px / 100
    fig, axes = plt.subplots(rows, columns, figsize=(inches, inches * rows / columns), dpi=100,
                             squeeze=False)
    edges = result.topology.edges
    gaits = result.summary["gait"].to_numpy()
    reach = np.nanmax(np.abs(shapes)) * 1.05
    lines = []
    for slot, ax in enumerate(axes.ravel()):
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        if slot >= len(chosen):
            ax.axis("off")
            continue
        ax.set_xlim(-reach, reach)
        ax.set_ylim(-reach, reach)
        ax.set_title(f"#{chosen[slot]} {gaits[chosen[slot]]}", fontsize=9)
        lines.append(ax.plot([], [], color="tab:blue", lw=1.2)[0])
    label = fig.suptitle("")
    fig.tight_layout(rect=(0, 0, 1, 0.95))

    def draw(index):
        for slot, line in enumerate(lines):
            line.set_data(*_polyline(shapes[index, slot], edges))
        label.set_text(f"t = {times[index]:.2f} s ({frame} frame, mm)")
        return lines

    movie = animation.FuncAnimation(fig, draw, frames=len(times), blit=False)
    if path.suffix.lower() == ".mp4":
        imageio_ffmpeg = require("imageio_ffmpeg", "video")
        matplotlib.rcParams["animation.ffmpeg_path"] = imageio_ffmpeg.get_ffmpeg_exe()
        writer = animation.FFMpegWriter(fps=fps)
    else:
        writer = animation.PillowWriter(fps=fps)
    path.parent.mkdir(parents=True, exist_ok=True)
    movie.save(path, writer=writer)
    plt.close(fig)
    return path


def _polyline(points: np.ndarray, edges: np.ndarray):
    """x, y arrays drawing every edge as a segment, NaN-separated (one Line2D for the robot)."""
    segments = np.full((len(edges), 3, 2), np.nan)
    segments[:, 0] = points[edges[:, 0]]
    segments[:, 1] = points[edges[:, 1]]
    flat = segments.reshape(-1, 2)
    return flat[:, 0], flat[:, 1]


def _body_frame(shapes_mm: np.ndarray, topology) -> np.ndarray:
    """Shapes (R, B, N, 2) moved so that the hub is at the origin and the hub-to-joint
    directions keep their rest orientation on average."""
    rest = topology.rest_positions
    joints = topology.joints
    now = shapes_mm[..., joints, :] - shapes_mm[..., CENTRE:CENTRE + 1, :]
    rest_arms = rest[joints] - rest[CENTRE]
    turn = np.arctan2(now[..., 1], now[..., 0]) - np.arctan2(rest_arms[:, 1], rest_arms[:, 0])
    angle = np.arctan2(np.sin(turn).sum(-1), np.cos(turn).sum(-1))
    cos, sin = np.cos(-angle)[..., None], np.sin(-angle)[..., None]
    centred = shapes_mm - shapes_mm[..., CENTRE:CENTRE + 1, :]
    return np.stack([cos * centred[..., 0] - sin * centred[..., 1],
                     sin * centred[..., 0] + cos * centred[..., 1]], axis=-1)

