"""Pictures of the robot with matplotlib (any backend; Agg for files and arrays): the one
drawing that `SimulationResult.animate`, `python -m studies animate` and the environments'
`render()` share.

The robot is drawn from its node positions (mm): foam limbs brown, spokes from the hub light
gray, actuator arcs dark gray, and red while hot (during the heating pulse, the first t0 =
`CurvatureProfile.switch_time` seconds after firing); the central cylinder; the labels A1..A8
beside their arcs (red while hot); optionally the centroid's path (a blue line, a dot where the
centroid is now) and a goal point.
"""

from __future__ import annotations

import math
from typing import Optional

import numpy as np

from .geometry import ARC, CENTRE, LIMB

LIMB_COLOUR = "saddlebrown"
SPOKE_COLOUR = "0.8"
RESTING_COLOUR = "0.45"
HOT_COLOUR = "red"
PATH_COLOUR = "tab:blue"
LABEL_OFFSET_MM = 8.0
"""How far beyond its arc's middle node an actuator's label sits, mm."""


def edge_actuators(topology) -> np.ndarray:
    """(E,) the actuator index 0..7 of every arc edge, -1 for limbs and spokes."""
    actuator_of_pair = {}
    for index, arc in enumerate(topology.arcs):
        for a, b in zip(arc[:-1], arc[1:]):
            actuator_of_pair[frozenset((int(a), int(b)))] = index
    return np.array([actuator_of_pair.get(frozenset((int(a), int(b))), -1) if kind == ARC else -1
                     for (a, b), kind in zip(topology.edges, topology.edge_kind)])


def hot_actuators(since_fired_s, heating_s: float, delays_s=0.0) -> np.ndarray:
    """Bool array, True where an actuator heats: its profile started less than `heating_s`
    ago, `delays_s` (8,) s after its firing (`StarParams.actuator_delays`: the profile waits
    that long), so 0 <= since − delay < heating_s; NaN (never fired) is not hot.
    `since_fired_s` (..., 8) s."""
    since = np.asarray(since_fired_s, dtype=np.float64) - np.asarray(delays_s, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return (since >= 0.0) & (since < heating_s)


def periodic_hot_actuators(times_s, fired, period_s: float, heating_s: float,
                           delays_s=0.0) -> np.ndarray:
    """(R, 8) bool: the actuators of a periodic gait that are hot at each time, a gait firing
    the `fired` (8,) bool actuators at 0, T, 2T, ... (as `simulate` does), each heating
    `delays_s` (8,) s after it fires (`hot_actuators`)."""
    phase = np.mod(np.asarray(times_s, dtype=np.float64), period_s)
    return hot_actuators(phase[:, None], heating_s, delays_s) & \
        np.asarray(fired, dtype=bool)[None, :]


def nice_length(span: float) -> float:
    """A round length (1, 2 or 5 times a power of ten) near a fifth of `span`, for a scale bar."""
    target = max(span / 5.0, 1e-9)
    power = 10.0 ** math.floor(math.log10(target))
    return min((power * m for m in (1.0, 2.0, 5.0, 10.0)), key=lambda v: abs(v - target))


def add_scale_bar(ax, length_mm: float):
    """A horizontal scale bar of `length_mm` (labelled) in the axes' lower right corner."""
    from matplotlib.offsetbox import AnchoredOffsetbox, AuxTransformBox, TextArea, VPacker
    from matplotlib.patches import Rectangle

    bar = AuxTransformBox(ax.transData)
    bar.add_artist(Rectangle((0, 0), length_mm, 0, linewidth=2.5, edgecolor="k"))
    text = TextArea(f"{length_mm:g} mm", textprops={"fontsize": 8})
    box = VPacker(children=[bar, text], align="center", pad=0, sep=3)
    ax.add_artist(AnchoredOffsetbox(loc="lower right", child=box, frameon=False, pad=0.4))


class RobotArtist:
    """One robot on a matplotlib Axes, redrawn with `update` (as an animation's frames).

    topology: the robot's `Topology`; cylinder_diameter_mm: the central cylinder, mm;
    labels: draw A1..A8 beside the arcs; path: draw the centroid's path given to `update`."""

    def __init__(self, ax, topology, cylinder_diameter_mm: float, labels: bool = True,
                 path: bool = True):
        from matplotlib.collections import LineCollection
        from matplotlib.patches import Circle

        self.topology = topology
        self.edge_actuator = edge_actuators(topology)
        kinds = topology.edge_kind
        self.base_colours = np.array([LIMB_COLOUR if k == LIMB else RESTING_COLOUR if k == ARC
                                      else SPOKE_COLOUR for k in kinds], dtype=object)
        self.base_widths = np.where(kinds == LIMB, 2.5, np.where(kinds == ARC, 1.6, 0.8))
        self.cylinder = Circle((0.0, 0.0), cylinder_diameter_mm / 2, facecolor="lightsteelblue",
                               edgecolor="k", lw=0.6, zorder=1)
        ax.add_patch(self.cylinder)
        self.lines = LineCollection([], zorder=2)
        ax.add_collection(self.lines)
        self.labels = ([ax.text(0.0, 0.0, f"A{m + 1}", ha="center", va="center", fontsize=7,
                                zorder=3) for m in range(len(topology.arcs))] if labels else [])
        # the line is the centroid's path so far, the dot its position now
        self.path = ax.plot([], [], color=PATH_COLOUR, lw=1.2, zorder=4, marker="o", ms=4,
                            markevery=[-1], label="centroid path")[0] if path else None
        self.ax = ax

    def update(self, positions_mm: np.ndarray, hot: np.ndarray,
               path_mm: Optional[np.ndarray] = None):
        """Draw the robot at `positions_mm` (N, 2) with the `hot` (8,) bool actuators in red;
        `path_mm` (k, 2): the centroid's path so far. Returns the artists drawn."""
        edges = self.topology.edges
        self.lines.set_segments(np.stack([positions_mm[edges[:, 0]], positions_mm[edges[:, 1]]],
                                         axis=1))
        hot_edge = (self.edge_actuator >= 0) & np.asarray(hot, dtype=bool)[self.edge_actuator]
        self.lines.set_color(np.where(hot_edge, HOT_COLOUR, self.base_colours).tolist())
        self.lines.set_linewidth(np.where(hot_edge, 2.4, self.base_widths))
        hub = positions_mm[CENTRE]
        self.cylinder.center = tuple(hub)
        for index, label in enumerate(self.labels):
            arc = self.topology.arcs[index]
            middle = positions_mm[arc[len(arc) // 2]]
            outward = middle - hub
            outward = outward / max(float(np.hypot(*outward)), 1e-12)
            label.set_position(tuple(middle + LABEL_OFFSET_MM * outward))
            label.set_color(HOT_COLOUR if hot[index] else "0.25")
        artists = [self.lines, self.cylinder, *self.labels]
        if self.path is not None and path_mm is not None:
            self.path.set_data(path_mm[:, 0], path_mm[:, 1])
            artists.append(self.path)
        return artists


def robot_image(positions_mm: np.ndarray, topology, hot: np.ndarray, cylinder_diameter_mm: float,
                goal_mm: Optional[np.ndarray] = None, path_mm: Optional[np.ndarray] = None,
                title: str = "", size_px: int = 400) -> np.ndarray:
    """One picture of the robot as an (size_px, size_px, 3) uint8 RGB array (Agg, no window):
    the robot at `positions_mm` (N, 2), the `hot` actuators red, an optional goal point and
    centroid path, a scale bar; the view is centred on the robot (and takes in the goal)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(size_px / 100, size_px / 100), dpi=100)
    canvas = FigureCanvasAgg(figure)
    ax = figure.add_axes((0.02, 0.02, 0.96, 0.90))
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    RobotArtist(ax, topology, cylinder_diameter_mm).update(positions_mm, hot, path_mm)
    points = positions_mm if goal_mm is None else np.vstack([positions_mm, goal_mm[None]])
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = 0.5 * (low + high), 0.5 * float((high - low).max()) + 12.0
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    if goal_mm is not None:
        ax.plot(*goal_mm, marker="*", color="tab:green", ms=12, zorder=5)
    add_scale_bar(ax, nice_length(2 * half))
    figure.suptitle(title, fontsize=9)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
