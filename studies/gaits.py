"""Every gait: the 255 non-empty actuator sets, simulated once per symmetry class (29 classes
under the octagon's 8 rotations and 8 reflections) and expanded back; where the eight actuators
differ (`primitives.actuators_equal` false: the identified preset's gains, a --set of one
actuator's field) a gait and its images are different robots, and every gait is simulated, its
own class (as the motion primitives do: `primitives.gait_sources`).

    python -m studies gaits [--cycles 3] [--arch cpu|gpu] [--out DIR] [--quick]
                            [--preset paper|accurate|identified] [--set NAME=VALUE ...]
                            [--workers N | --scheduler tcp://HOST:PORT]

Writes `gaits.csv` (one row per gait: gait, class_representative, class_size, rotation and
reflection mapping the representative onto it, whole-run and steady speeds, travel direction
and travel direction relative to the gait's forward direction (NaN for a gait that does not
move), heading (body rotation at the end), status),
`gaits_classes.csv` (the 29 simulated instances, or 255, full summary) and `gaits.png` (the
classes ranked by speed, each bar with an actuator pictogram).

From Python: `expand_classes(summary)` maps a summary of the class representatives onto all 255
gaits with the symmetry functions of `taichi_star.primitives`, which the motion primitives use
too: `class_symmetries` gives the octagon symmetry taking each representative onto its gaits,
`transform_direction` and `transform_rotation` map a direction and a body rotation by it, and
`sort_gaits` orders the rows.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Optional

import numpy as np
import pandas as pd

from taichi_star import StarParams
from taichi_star.batch import run_batch
from taichi_star.gait import N_ACTUATORS, Gait
from taichi_star.metrics import wrap_degrees
from taichi_star.primitives import (GaitSources, actuators_equal, class_symmetries,
                                    gait_sources, simulated_gaits, sort_gaits,
                                    transform_direction, transform_rotation)

from . import cli

DESCRIPTION = ("All 255 gaits, one simulation per octagon symmetry class (29; every gait where "
               "the actuators differ), ranked by speed.")

ZERO_SPEED_MM_S = 1e-9
"""Below this speed (mm/s; ~1e-8 mm over a few cycles, the solver's resolution) a gait is taken
as not moving at all, as the symmetric gaits without a forward direction do, and its travel
direction is reported as NaN rather than the direction of round-off."""

GAITS_COLUMNS = ["gait", "class_representative", "class_size", "rotation", "reflected",
                 "speed_mm_s", "signed_speed_mm_s", "steady_speed_mm_s",
                 "steady_signed_speed_mm_s", "travel_direction_deg",
                 "travel_direction_relative_deg", "heading_deg", "n_actuators", "status"]


def relative_direction(gait: str, direction_deg: float) -> float:
    """A direction relative to the gait's forward direction, degrees in (-180, 180]; NaN where
    the forward direction is undefined."""
    forward = Gait.parse(gait).forward
    if forward is None or not math.isfinite(direction_deg):
        return math.nan
    return float(wrap_degrees(direction_deg - math.degrees(math.atan2(forward[1], forward[0])),
                              include_180=True))


def class_params(base: StarParams = StarParams()):
    """One StarParams per gait to simulate: each symmetry class representative, or every
    gait where the actuators differ (`primitives.gait_sources`; the gaits read from them once
    copied the representatives' runs onto robots that are not their images: an audit,
    2026-12)."""
    return [base.replace(gait=gait)
            for gait in simulated_gaits(gait_sources(actuators_equal(base)))]


def expand_classes(summary: pd.DataFrame, sources: Optional[GaitSources] = None) -> pd.DataFrame:
    """All gaits from a summary of the simulated gaits (rows matched by gait), each read from
    its source by `sources` (default `primitives.class_symmetries`, the representatives; for
    a robot whose actuators differ `primitives.gait_sources(False)`, each gait its own): the same
    speeds, the travel direction and the heading mapped by the symmetry
    (`primitives.transform_direction`, `primitives.transform_rotation`). Columns
    GAITS_COLUMNS; 255 rows sorted by (number of actuators, bitmask): `primitives.sort_gaits`."""
    by_gait = {row["gait"]: row for _, row in summary.iterrows()}
    rows = []
    for gait, (rep, rotation, reflect, class_size) in (sources or class_symmetries()).items():
        source = by_gait[rep]
        ok = source["status"] == "ok"
        moving = ok and float(source["speed_mm_s"]) >= ZERO_SPEED_MM_S
        direction = (transform_direction(float(source["travel_direction_deg"]), rotation,
                                         reflect) if moving else math.nan)
        rows.append({
            "gait": gait, "class_representative": rep, "class_size": class_size,
            "rotation": rotation, "reflected": reflect,
            "speed_mm_s": source["speed_mm_s"] if ok else math.nan,
            "signed_speed_mm_s": source["signed_speed_mm_s"] if ok else math.nan,
            "steady_speed_mm_s": source["steady_speed_mm_s"] if ok else math.nan,
            "steady_signed_speed_mm_s": (source["steady_signed_speed_mm_s"] if ok
                                         else math.nan),
            "travel_direction_deg": direction,
            "travel_direction_relative_deg": relative_direction(gait, direction),
            "heading_deg": (transform_rotation(float(source["heading_deg"]), reflect)
                            if ok else math.nan),
            "n_actuators": len(Gait.parse(gait).actuators),
            "status": source["status"],
        })
    return sort_gaits(pd.DataFrame(rows, columns=GAITS_COLUMNS))


def plot_gaits(csv_path, png_path):
    """Classes ranked by speed, from a gaits CSV: one bar per class (coloured by the sign of the
    signed speed), labelled with the representative, its class size and an actuator pictogram
    (filled dots = fired actuators, A1 on the right, counter-clockwise)."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    classes = table.drop_duplicates("class_representative").copy()
    classes = classes.sort_values("speed_mm_s", ascending=True, na_position="first")
    n = len(classes)
    fig = plt.figure(figsize=(8, max(3.0, 0.3 * n + 1.0)))
    grid = fig.add_gridspec(1, 2, width_ratios=[1, 9], wspace=0.02)
    pict = fig.add_subplot(grid[0])
    ax = fig.add_subplot(grid[1], sharey=pict)
    y = np.arange(n)
    speeds = classes["speed_mm_s"].to_numpy(dtype=float)
    signed = classes["signed_speed_mm_s"].to_numpy(dtype=float)
    colours = ["tab:blue" if s > 0 else "tab:orange" if s < 0 else "tab:gray" for s in signed]
    ax.barh(y, np.nan_to_num(speeds), color=colours)
    for i, (_, row) in enumerate(classes.iterrows()):
        label = f"{row['class_representative']} (x{row['class_size']})"
        if row["status"] != "ok":
            label += f" [{row['status']}]"
        ax.text(np.nan_to_num(speeds[i]), i, " " + label, va="center", fontsize=7)
    angles = np.radians(45.0 * np.arange(N_ACTUATORS))
    for i, rep in enumerate(classes["class_representative"]):
        fired = set(Gait.parse(rep).actuators)
        px, py = 0.36 * np.cos(angles), i + 0.36 * np.sin(angles)
        pict.plot(np.append(px, px[0]), np.append(py, py[0]), color="0.7", lw=0.6)
        pict.scatter(px, py, s=9, c=["k" if m + 1 in fired else "white" for m in range(8)],
                     edgecolors="k", linewidths=0.4, zorder=3)
    ax.set_ylim(-0.7, n - 0.3)
    box = pict.get_position()
    inches_per_unit = box.height * fig.get_figheight() / n
    half_width = 0.5 * box.width * fig.get_figwidth() / inches_per_unit
    pict.set_xlim(-half_width, half_width)
    pict.axis("off")
    ax.set_yticks([])
    finite = speeds[np.isfinite(speeds)]
    ax.set_xlim(0, (finite.max() if len(finite) else 1.0) * 1.45)
    ax.set_xlabel("speed (mm/s)   [blue: forward, orange: reverse, gray: no forward direction]")
    duration = pd.read_csv(Path(csv_path).with_name("gaits_classes.csv"))["duration_s"].iloc[0] \
        if Path(csv_path).with_name("gaits_classes.csv").exists() else math.nan
    settings = cli.run_settings(csv_path)
    ax.set_title(f"{n} gait classes ranked by speed over {duration:g} s from rest"
                 + (f"\n{settings}" if settings else ""), fontsize=9)
    cli.write_figure(fig, png_path, dpi=130, bbox_inches="tight")
    plt.close(fig)
    return Path(png_path)


def build_parser():
    parser = cli.StudyParser("gaits", DESCRIPTION)
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    cli.add_execution_flags(parser)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    base = cli.base_params(args)
    params = class_params(base)
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    with cli.executor(args, out) as executor:
        result = run_batch(params, **cli.run_length(args), solver=solver, arch=args.arch,
                           chunk_size=cli.chunk_size(args, len(params), executor.n_workers),
                           executor=executor, progress=not args.no_progress)
    out.write_csv(result.summary, "gaits_classes.csv")
    table = expand_classes(result.summary, gait_sources(actuators_equal(base)))
    csv = out.write_csv(table, "gaits.csv")
    out.wrote(plot_gaits(csv, out.path("gaits.png")))
    out.report()
    return table
