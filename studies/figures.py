"""Fig. 4c and 4b of the paper, shared by the studies that draw them (`fig4c`, and `calibrate` at
its best point): the five gaits run on one model, their tables and plots.

`run_fig4c(out, base, solver, duration_s=...)` simulates the paper's gaits on `base` and writes,
each table with its provenance sidecar, `<prefix>.csv` (`compare_with_experiment`),
`<prefix>_summary.csv`, the Fig. 4b displacement table and both plots drawn from the CSVs.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from taichi_star import SolverConfig, StarParams
from taichi_star.batch import run_batch
from taichi_star.experiment import PAPER_GAITS, compare_with_experiment, experimental_trajectory
from taichi_star.timegrid import interval_for_count

from . import cli

RECORDS = 150
"""About this many centroid records per run (for Fig. 4b)."""


def fig4c_params(base: StarParams, gaits: Sequence[str] = PAPER_GAITS):
    """One StarParams per gait, on top of `base`."""
    return [base.replace(gait=g) for g in gaits]


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


def plot_fig4c(csv_path, png_path, title: str = None, caption: str = None):
    """Grouped bars from a fig4c CSV: simulated |speed| next to the experiment, per gait; the
    simulated direction is written on each bar (red when it disagrees with the paper).
    `caption` (default: the model and solver from the CSV's sidecar) goes under the plot."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    x = np.arange(len(table))
    width = 0.38
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
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
    ax.set_xticks(x, list(table["gait"]))
    ax.set_xlabel("gait (actuators fired together each cycle)")
    ax.set_ylabel("speed (mm/s)")
    ax.set_title(title or fig4_titles()[0], fontsize=9)
    ax.legend()
    _caption(fig, csv_path, caption)
    cli.write_figure(fig, png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def plot_fig4b(csv_path, png_path, title: str = None, caption: str = None):
    """Displacement against time from a fig4b CSV, one panel per gait: simulation solid blue,
    experiment dashed gray (each panel has its own scale: A1 moves millimetres, A1+A3+A5
    tens). `caption` (default: the model and solver from the sidecar) goes under the plot."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    gaits = list(dict.fromkeys(table["gait"]))
    columns = min(3, len(gaits))
    rows = int(np.ceil(len(gaits) / columns))
    fig, axes = plt.subplots(rows, columns, figsize=(3.0 * columns, 2.5 * rows + 0.9),
                             sharex=True, squeeze=False)
    for ax, gait in zip(axes.ravel(), gaits):
        for source, style, colour in (("simulation", "-", "tab:blue"),
                                      ("experiment", "--", "tab:gray")):
            part = table[(table["gait"] == gait) & (table["source"] == source)]
            if len(part):
                ax.plot(part["t_s"], part["displacement_mm"], style, color=colour,
                        label=source)
        ax.set_title(gait, fontsize=9)
        ax.tick_params(labelsize=8)
        ax.grid(alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_ylabel("displacement (mm)", fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)", fontsize=8)
    for ax in axes.ravel()[len(gaits):]:
        ax.axis("off")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    spare = axes.ravel()[len(gaits)] if len(gaits) < axes.size else None
    if spare is not None:
        spare.legend(handles, labels, loc="center", fontsize=9, frameon=False)
    else:
        axes[0, 0].legend(fontsize=7)
    fig.suptitle(title or fig4_titles()[1], fontsize=10)
    _caption(fig, csv_path, caption)
    cli.write_figure(fig, png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def _caption(fig, csv_path, caption):
    """Lay the figure out with `caption` (default: the model and solver of the CSV's sidecar,
    `cli.run_settings`) in small gray text at its bottom."""
    text = caption if caption is not None else cli.run_settings(csv_path)
    fig.tight_layout(rect=(0, 0.05 if text else 0, 1, 1))
    if text:
        fig.text(0.01, 0.01, textwrap.fill(text, 130), fontsize=7, color="0.35", ha="left",
                 va="bottom")


def run_fig4c(out: cli.Output, base: StarParams, solver: SolverConfig, *, duration_s: float,
              arch: str = "cpu", prefix: str = "fig4c", progress: bool = True,
              title_note: str = "") -> pd.DataFrame:
    """Simulate the five paper gaits on `base` for `duration_s` seconds from rest and write
    `<prefix>.csv` (the Fig. 4c table), `<prefix>_summary.csv` (the full summary), the Fig. 4b
    table (`fig4b` in place of `fig4c` in the prefix, else `<prefix>_fig4b`) and both plots
    into `out`; `title_note` (e.g. "calibrated (alpha=0.8)") and the model and solver settings
    go into the plots' captions.
    Returns the Fig. 4c table."""
    params = fig4c_params(base)
    result = run_batch(params, duration_s, solver=solver, arch=arch,
                       record_interval_s=interval_for_count(duration_s, RECORDS, solver.dt),
                       progress=progress)
    fig4b_prefix = prefix.replace("fig4c", "fig4b") if "fig4c" in prefix else prefix + "_fig4b"
    table_csv = out.write_csv(compare_with_experiment(result.summary), f"{prefix}.csv")
    out.write_csv(result.summary, f"{prefix}_summary.csv")
    curves_csv = out.write_csv(fig4b_table(result.summary, result.trajectory, duration_s),
                               f"{fig4b_prefix}.csv")
    title_4c, title_4b = fig4_titles(duration_s)
    caption = "; ".join(part for part in (title_note, cli.run_settings(table_csv)) if part)
    out.wrote(plot_fig4c(table_csv, out.path(f"{prefix}.png"), title=title_4c, caption=caption),
              plot_fig4b(curves_csv, out.path(f"{fig4b_prefix}.png"), title=title_4b,
                         caption=caption))
    return pd.read_csv(table_csv)


def fig4_titles(duration_s: float = None):
    """(Fig. 4c title, Fig. 4b title) in plain words; the model and solver settings go in the
    caption (and the sidecar), not the title."""
    span = f"the first {duration_s:g} s from rest" if duration_s else "from rest"
    # the experiment's bars are whole trials' speeds (22-61 s), not the simulated span (the
    # title gave both the span: an audit, 2026-12)
    return (f"How fast each gait swims: simulation ({span}) vs. experiment (whole trials)\n"
            "labels: swimming direction (fwd/rev); red = opposite to the paper",
            f"How far each gait's centre moves ({span}): simulation vs. experiment")
