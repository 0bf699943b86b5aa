"""Fig. 4c and 4b of the paper: the five gaits at the paper's parameters, 3 cycles from rest.

    python -m studies fig4c [--arch cpu|gpu] [--out results/] [--quick]
                            [--discretisation paper|converged] [--cycles 3] [--set NAME=VALUE ...]

Writes (prefix `fig4c` by default):
- `fig4c.csv`: gait, sim_speed_mm_s, sim_signed_speed_mm_s, sim_direction, exp_speed_mm_s,
  exp_cycle_speed_std_mm_s, paper_direction, direction_matches, speed_ratio, status (experiment:
  full-trial speeds, and the spread of its per-cycle speeds drawn as error bars);
- `fig4c_summary.csv`: the full simulation summary (every parameter, speeds over cycles 0-3 and
  1-3, Newton statistics, status);
- `fig4b.csv`: centroid displacement against time, simulation and experiment (long form);
- `fig4c.png` (grouped bars, simulation next to experiment) and `fig4b.png` (displacement
  against time, simulation solid, experiment dashed), drawn from the CSVs above.

From Python: `run_fig4c(out_dir, overrides={"alpha": 1.0})` returns the Fig. 4c table.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from taichi_star.experiment import (PAPER_GAITS, compare_with_experiment,
                                    experimental_trajectory)
from taichi_star.params import SolverConfig, StarParams

from . import common

DESCRIPTION = ("The paper's Fig. 4c/4b: speed of the five gaits (A1, A1+A2, A1+A3, A1+A4, "
               "A1+A3+A5), simulation vs experiment, 3 cycles from rest.")


def fig4c_params(base: StarParams = StarParams(), gaits: Sequence[str] = PAPER_GAITS):
    """One StarParams per gait, on top of `base`."""
    return [base.replace(gait=g) for g in gaits]


def fig4c_table(summary: pd.DataFrame) -> pd.DataFrame:
    """The Fig. 4c table from a simulate summary (see taichi_star.experiment)."""
    return compare_with_experiment(summary)


def record_stride(total_steps: int, per_cycle=None, frames_per_cycle: int = 60) -> int:
    """A recording stride that hits every cycle boundary (when `per_cycle` is an integer) with
    about `frames_per_cycle` records per cycle; otherwise ~150 records in all."""
    if per_cycle:
        target = max(1, per_cycle // frames_per_cycle)
        return max(d for d in range(1, target + 1) if per_cycle % d == 0)
    return max(1, total_steps // 150)


def fig4b_table(summary: pd.DataFrame, trajectory: pd.DataFrame, duration_s: float) -> pd.DataFrame:
    """Long table of centroid displacement against time: gait, source ("simulation" or
    "experiment"), t_s, x_mm, y_mm, displacement_mm (distance from the start); the experiment
    is cut at `duration_s` and aligned at t = 0."""
    parts = []
    for _, row in summary.iterrows():
        sim = trajectory[trajectory["instance"] == row["instance"]]
        parts.append(pd.DataFrame({
            "gait": row["gait"], "source": "simulation", "t_s": sim["t_s"].to_numpy(),
            "x_mm": sim["x_mm"].to_numpy(), "y_mm": sim["y_mm"].to_numpy()}))
        try:
            exp = experimental_trajectory(row["gait"])
        except ValueError:
            continue
        exp = exp[exp["t_s"] <= duration_s + 1e-9]
        parts.append(pd.DataFrame({
            "gait": row["gait"], "source": "experiment", "t_s": exp["t_s"].to_numpy(),
            "x_mm": exp["x_mm"].to_numpy(), "y_mm": exp["y_mm"].to_numpy()}))
    table = pd.concat(parts, ignore_index=True)
    table["displacement_mm"] = np.hypot(table["x_mm"], table["y_mm"])
    return table


def plot_fig4c(csv_path, png_path, title: str = None):
    """Grouped bars from a fig4c CSV: simulated |speed| next to the experiment (error bar: the
    std of its per-cycle speeds), per gait; the simulated direction is written on each bar (red
    when it disagrees with the paper)."""
    plt = common.use_agg()
    table = pd.read_csv(csv_path)
    x = np.arange(len(table))
    width = 0.38
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    ax.bar(x - width / 2, table["sim_speed_mm_s"], width, label="simulation", color="tab:blue")
    # error bars: the spread (± 1 std) of the measured per-cycle speeds (older CSVs lack it)
    spread = table["exp_cycle_speed_std_mm_s"] if "exp_cycle_speed_std_mm_s" in table else None
    ax.bar(x + width / 2, table["exp_speed_mm_s"], width, yerr=spread, capsize=3,
           label="experiment (± per-cycle std)", color="tab:gray")
    for i, row in table.iterrows():
        height = row["sim_speed_mm_s"]
        if isinstance(row["status"], str) and row["status"] != "ok":
            label, colour, height = row["status"], "red", 0.0
        else:
            short = {"forward": "fwd", "reverse": "rev"}.get(row["sim_direction"], "?")
            label = short
            colour = "black" if bool(row["direction_matches"]) else "red"
        ax.text(i - width / 2, (height if np.isfinite(height) else 0.0), label, ha="center",
                va="bottom", fontsize=8, color=colour)
        paper = {"forward": "fwd", "reverse": "rev"}.get(row["paper_direction"], "?")
        top = row["exp_speed_mm_s"] + (spread[i] if spread is not None else 0.0)
        ax.text(i + width / 2, top if np.isfinite(top) else 0.0, paper, ha="center",
                va="bottom", fontsize=8)
    ax.set_xticks(x, [g.replace("+", "&") for g in table["gait"]])
    ax.set_ylabel("speed (mm/s)")
    ax.set_title(title or "Fig. 4c: swimming speed, 3 cycles from rest "
                          "(labels: direction; red = disagrees with the paper)", fontsize=9)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def plot_fig4b(csv_path, png_path, title: str = None):
    """Displacement against time from a fig4b CSV: simulation solid, experiment dashed, one
    colour per gait."""
    plt = common.use_agg()
    table = pd.read_csv(csv_path)
    fig, ax = plt.subplots(figsize=(7.5, 4.2))
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, gait in enumerate(dict.fromkeys(table["gait"])):
        colour = colours[i % len(colours)]
        for source, style in (("simulation", "-"), ("experiment", "--")):
            part = table[(table["gait"] == gait) & (table["source"] == source)]
            if len(part):
                ax.plot(part["t_s"], part["displacement_mm"], style, color=colour,
                        label=f"{gait.replace('+', '&')} ({source[:3]}.)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("centroid displacement (mm)")
    ax.set_title(title or "Fig. 4b: centroid displacement (simulation solid, experiment dashed)",
                 fontsize=9)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def run_fig4c(out, base: StarParams = StarParams(), overrides: Mapping = None,
              cycles: float = 3.0, solver: SolverConfig = SolverConfig(), arch: str = "cpu",
              quick: bool = False, prefix: str = "fig4c", progress: bool = True,
              title_note: str = "") -> pd.DataFrame:
    """Run the five gaits, write `<prefix>.csv`, `<prefix>_summary.csv`, the fig4b CSV and both
    plots into `out`, and return the Fig. 4c table."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if overrides:
        try:
            base = base.replace(**dict(overrides))
        except (ValueError, TypeError) as error:
            raise common.StudyArgumentError(f"invalid parameter value: {error}") from None
    params = fig4c_params(base)
    duration = common.QUICK_DURATION_S if quick else cycles * base.period
    total_steps = int(round(duration / solver.dt))
    per_cycle = None if quick else common.steps_per_cycle(base.period, solver.dt)
    stride = record_stride(total_steps, per_cycle)
    result = common.run_batch(params, duration_s=duration, solver=solver, arch=arch,
                              record_every=stride, progress=progress)
    summary = result.summary

    fig4b_prefix = prefix.replace("fig4c", "fig4b") if "fig4c" in prefix else prefix + "_fig4b"
    paths = [common.write_csv(fig4c_table(summary), out / f"{prefix}.csv"),
             common.write_csv(summary, out / f"{prefix}_summary.csv"),
             common.write_csv(fig4b_table(summary, result.trajectory, duration),
                              out / f"{fig4b_prefix}.csv")]
    note = f" {title_note}" if title_note else ""
    paths.append(plot_fig4c(paths[0], out / f"{prefix}.png",
                            title=(f"Fig. 4c{note}: speed over {duration:g} s from rest\n"
                                   f"(labels: direction; red = disagrees with the paper)")))
    paths.append(plot_fig4b(paths[2], out / f"{fig4b_prefix}.png",
                            title=f"Fig. 4b{note}: centroid displacement (simulation solid, "
                                  f"experiment dashed)"))
    print(common.describe(paths))
    return pd.read_csv(paths[0])


def build_parser():
    parser = common.common_parser("fig4c", DESCRIPTION)
    parser.add_argument("--cycles", type=float, default=3.0,
                        help="actuation cycles from rest (default 3, as the paper)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="override one StarParams field for all gaits, e.g. --set alpha=1.0")
    parser.add_argument("--prefix", default="fig4c", help="output file prefix (default fig4c)")
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    common.check_positive(args.cycles, "--cycles")
    overrides = common.parse_overrides(args.set)
    if "gait" in overrides:
        raise common.StudyArgumentError("--set gait=...: fig4c always runs the five paper gaits")
    base = common.base_params(args)
    try:
        base.replace(**overrides)
    except (ValueError, TypeError) as error:
        raise common.StudyArgumentError(f"--set: {error}") from None
    table = run_fig4c(args.out, base=base, overrides=overrides, cycles=args.cycles,
                      solver=common.solver_for(args), arch=args.arch, quick=args.quick,
                      prefix=args.prefix, progress=not args.no_progress)
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(table.to_string(index=False))
    return table
