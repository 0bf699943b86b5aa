"""Discretisation convergence: the five paper gaits' speeds against n_arc, for the paper's
clamped actuation ends and the shared-ends correction, with the extrapolated limit.

    python -m studies convergence [--quick] [--cycles 1] [--n-arc 18,36,72,144]
                                  [--preset paper|accurate] [--set NAME=VALUE ...] [--out DIR]

For each actuation_ends variant the speeds of successive doublings of n_arc give the observed
order p = log2(ΔS_coarse / ΔS_fine) and a Richardson limit S_lim = S_fine + ΔS_fine/(2^p − 1)
(first order: 2·S_fine − S_coarse); the error of every run is taken against the clamped-ends
limit of its gait (or the shared one where the clamped series has none).

Writes `convergence.csv` (one row per run: gait, actuation_ends, n_arc, n_nodes, speeds, the
gait's limit, relative error, observed order) and `convergence.png` (relative error against
n_arc, log-log, one line per gait and variant, the 1 % line dashed).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from taichi_star import StarParams, metrics
from taichi_star.batch import run_batch
from taichi_star.experiment import PAPER_GAITS

from . import cli

DESCRIPTION = ("Discretisation convergence: speed against n_arc for clamped and shared "
               "actuation ends, Richardson limit.")
DEFAULT_N_ARC = "18,36,72,144"
QUICK_N_ARC = "4,8,16"
QUICK_GAITS = ("A1+A2",)
ACTUATION_ENDS = ("clamped", "shared")


def build_parser():
    parser = cli.StudyParser("convergence", DESCRIPTION)
    parser.add_argument("--n-arc", default=DEFAULT_N_ARC, quick=QUICK_N_ARC,
                        help="comma list of n_arc, each the double of the previous")
    cli.add_model_flags(parser, fixed=("gait", "n_arc", "actuation_ends"))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser, default=1.0)
    parser.add_argument("--chunk-size", type=int, default=None,
                        help="instances per simulate call (default: one per n_arc)")
    return parser


def parse_n_arc(text: str):
    n_arcs = cli.parse_values(text, "--n-arc", int)
    if len(n_arcs) < 3 or any(n < 2 for n in n_arcs) or any(
            b != 2 * a for a, b in zip(n_arcs, n_arcs[1:])):
        raise cli.StudyArgumentError(
            f"--n-arc needs at least three values >= 2, each twice the previous (for the "
            f"observed order), got {text!r}")
    try:
        StarParams(n_arc=n_arcs[-1])  # the finest, as StarParams bounds it
    except ValueError as error:
        raise cli.StudyArgumentError(f"--n-arc: {error}") from None
    return n_arcs


def convergence_params(base, n_arcs, gaits):
    """Every (gait, actuation_ends, n_arc) run, in that order."""
    return [base.replace(gait=g, n_arc=n, actuation_ends=ends)
            for g in gaits for ends in ACTUATION_ENDS for n in n_arcs]


def convergence_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Observed order, Richardson limit and relative errors from a summary with columns gait,
    actuation_ends, n_arc, n_limb, speed_mm_s, signed_speed_mm_s, status: of the signed speeds
    (the magnitudes hid a robot that reverses between meshes, A1 with shared ends, and read
    a reversal as convergence; an audit, 2026-12), so limit_mm_s is signed too."""
    rows = summary[["gait", "actuation_ends", "n_arc", "n_limb", "speed_mm_s", "signed_speed_mm_s",
                    "status"]].copy()
    rows["n_nodes"] = StarParams.node_count(rows.n_arc, rows.n_limb)
    rows["observed_order"] = np.nan
    rows["limit_mm_s"] = np.nan
    for (gait, ends), part in rows.groupby(["gait", "actuation_ends"], sort=False):
        series = part.sort_values("n_arc")
        speeds = series.signed_speed_mm_s.to_numpy()
        doubling = np.diff(series.n_arc.to_numpy()) == series.n_arc.to_numpy()[:-1]
        if len(speeds) < 3 or not doubling[-2:].all():
            continue
        order = float(metrics.observed_order(speeds[-2] - speeds[-3], speeds[-1] - speeds[-2]))
        limit = float(metrics.richardson_limit(speeds[-2], speeds[-1], order))
        rows.loc[series.index, "observed_order"] = order
        rows.loc[series.index, "limit_mm_s"] = limit
    limits = rows.dropna(subset=["limit_mm_s"]).groupby(["gait", "actuation_ends"]).limit_mm_s.first()
    # the clamped series (the model as specified) gives the reference limit; the shared one
    # where the clamped series has none
    reference = {gait: limits.get((gait, "clamped"), limits.get((gait, "shared"), math.nan))
                 for gait in rows.gait.unique()}
    rows["reference_limit_mm_s"] = rows.gait.map(reference)
    rows["relative_error"] = metrics.speed_error(rows.signed_speed_mm_s,
                                                 rows.reference_limit_mm_s, floor_mm_s=0.0)
    return rows.reset_index(drop=True)


def plot_convergence(csv_path, png_path):
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    table = table[table.relative_error > 0]  # a log axis: runs without a limit are left out
    fig, ax = plt.subplots(figsize=(8, 5.5), layout="constrained")
    for (gait, ends), part in table.groupby(["gait", "actuation_ends"]):
        part = part.sort_values("n_arc")
        ax.plot(part.n_arc, part.relative_error, "o-" if ends == "shared" else "s--",
                label=f"{gait}, {ends}")
    ax.axhline(0.01, color="k", ls=":", lw=1, label="1 %")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("n_arc (edges per actuator arc)")
    ax.set_ylabel("relative speed error vs extrapolated limit")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    settings = cli.run_settings(csv_path, mesh=False)
    ax.set_title("discretisation convergence of the speed" + (f" ({settings})" if settings
                                                              else ""), fontsize=9)
    cli.write_figure(fig, png_path, dpi=120)
    plt.close(fig)
    return png_path


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    n_arcs = parse_n_arc(args.n_arc)
    base = cli.base_params(args)
    gaits = QUICK_GAITS if args.quick else PAPER_GAITS
    params = convergence_params(base, n_arcs, gaits)
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    batch = run_batch(params, **cli.run_length(args), solver=solver, arch=args.arch,
                      chunk_size=args.chunk_size or len(params), progress=not args.no_progress)
    table = convergence_table(batch.summary)
    csv_path = out.write_csv(table, "convergence.csv")
    out.wrote(plot_convergence(csv_path, out.path("convergence.png")))
    out.report()
    return table
