"""Discretisation convergence (design §2.7): the five paper gaits' speeds against n_arc, for the
paper's clamped actuation ends and the shared-ends correction, with the extrapolated limit.

    python -m studies convergence [--quick] [--cycles 1] [--n-arc 18,36,72,144]

For each actuation_ends variant the speeds of successive doublings of n_arc give the observed
order p = log2(ΔS_coarse / ΔS_fine) and a Richardson limit S_lim = S_fine + ΔS_fine/(2^p − 1)
(first order: 2·S_fine − S_coarse); the error of every run is taken against the clamped-ends
limit of its gait (both variants extrapolate to the same limit within 0.2 % except A1, whose
shared series converges slowest). The converged preset (`StarParams.converged()`) is run too, so the table shows
whether it meets the design's ≤ 1 %.

Writes `convergence.csv` (one row per run: gait, actuation_ends, n_arc, n_nodes, speeds, the
gait's limit, relative error, observed order, run time share) and `convergence.png` (relative
error against n_arc, log-log, one line per gait and variant, the 1 % line dashed).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from taichi_star.experiment import PAPER_GAITS
from taichi_star.geometry import build_topology
from taichi_star.params import ACTUATION_ENDS, CONVERGED_DISCRETISATION, StarParams

from . import common

DESCRIPTION = ("Discretisation convergence: speed against n_arc for clamped and shared "
               "actuation ends, Richardson limit, error of the converged preset.")
DEFAULT_N_ARC = "18,36,72,144"
QUICK_N_ARC = "4,8,16"
QUICK_GAITS = ("A1+A2",)


def build_parser():
    parser = common.common_parser("convergence", DESCRIPTION)
    parser.add_argument("--n-arc", default=None,
                        help=f"comma list of n_arc, each the double of the previous "
                             f"(default {DEFAULT_N_ARC}; --quick {QUICK_N_ARC})")
    parser.add_argument("--cycles", type=float, default=None,
                        help="actuation cycles from rest (default 1; --quick: 0.2 s)")
    return parser


def parse_args(argv):
    args = build_parser().parse_args(argv)
    text = args.n_arc or (QUICK_N_ARC if args.quick else DEFAULT_N_ARC)
    args.n_arc = common.parse_values(text, "--n-arc", int)
    if len(args.n_arc) < 3 or any(n < 2 for n in args.n_arc) or any(
            b != 2 * a for a, b in zip(args.n_arc, args.n_arc[1:])):
        raise common.StudyArgumentError(
            f"--n-arc needs at least three values >= 2, each twice the previous (for the "
            f"observed order), got {text!r}")
    if args.cycles is not None:
        common.check_positive(args.cycles, "--cycles")
    args.cycles = args.cycles or 1.0
    return args


def convergence_params(n_arcs, gaits):
    """Every (gait, actuation_ends, n_arc) run plus the converged preset, in that order."""
    params = [StarParams(gait=g, n_arc=n, actuation_ends=ends)
              for g in gaits for ends in ACTUATION_ENDS for n in n_arcs]
    return params + [StarParams.converged(gait=g) for g in gaits]


def convergence_table(summary: pd.DataFrame) -> pd.DataFrame:
    """Observed order, Richardson limit and relative errors from a summary with columns gait,
    actuation_ends, n_arc, signed_speed_mm_s; the preset's rows are those at its n_arc."""
    rows = summary[["gait", "actuation_ends", "n_arc", "n_limb", "speed_mm_s", "signed_speed_mm_s",
                    "status"]].copy()
    rows["n_nodes"] = [build_topology(StarParams(n_arc=n, n_limb=m)).n_nodes
                       for n, m in zip(rows.n_arc, rows.n_limb)]
    preset = CONVERGED_DISCRETISATION
    rows["converged_preset"] = ((rows.n_arc == preset["n_arc"]) & (rows.n_limb == preset["n_limb"])
                                & (rows.actuation_ends == preset["actuation_ends"]))
    rows["observed_order"] = np.nan
    rows["limit_mm_s"] = np.nan
    for (gait, ends), part in rows[~rows.converged_preset].groupby(["gait", "actuation_ends"],
                                                                    sort=False):
        series = part.sort_values("n_arc")
        speeds = series.speed_mm_s.to_numpy()
        doubling = np.diff(series.n_arc.to_numpy()) == series.n_arc.to_numpy()[:-1]
        if len(speeds) < 3 or not doubling[-2:].all():
            continue
        coarse, fine = speeds[-2] - speeds[-3], speeds[-1] - speeds[-2]
        order = math.log2(coarse / fine) if coarse * fine > 0 else math.nan
        limit = speeds[-1] + fine / (2.0 ** order - 1.0) if math.isfinite(order) else math.nan
        rows.loc[series.index, "observed_order"] = order
        rows.loc[series.index, "limit_mm_s"] = limit
    limits = rows.dropna(subset=["limit_mm_s"]).groupby(["gait", "actuation_ends"]).limit_mm_s.first()
    # the clamped series (the model as specified) gives the reference limit; the shared one
    # where the clamped series has none
    reference = {gait: limits.get((gait, "clamped"), limits.get((gait, "shared"), math.nan))
                 for gait in rows.gait.unique()}
    rows["reference_limit_mm_s"] = rows.gait.map(reference)
    rows["relative_error"] = (rows.speed_mm_s - rows.reference_limit_mm_s).abs() \
        / rows.reference_limit_mm_s
    return rows.reset_index(drop=True)


def plot_convergence(csv_path, png_path):
    plt = common.use_agg()
    table = pd.read_csv(csv_path)
    table = table[table.relative_error > 0]  # a log axis: runs without a limit are left out
    fig, ax = plt.subplots(figsize=(8, 5.5), layout="constrained")
    for (gait, ends), part in table[~table.converged_preset].groupby(["gait", "actuation_ends"]):
        part = part.sort_values("n_arc")
        ax.plot(part.n_arc, part.relative_error, "o-" if ends == "shared" else "s--",
                label=f"{gait}, {ends}")
    preset = table[table.converged_preset]
    ax.plot(preset.n_arc, preset.relative_error, "k*", markersize=12,
            label="StarParams.converged()")
    ax.axhline(0.01, color="k", ls=":", lw=1, label="1 %")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ax.set_xlabel("n_arc (edges per actuator arc)")
    ax.set_ylabel("relative speed error vs extrapolated limit")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("discretisation convergence of the speed (design §2.7)", fontsize=9)
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
    return png_path


def main(argv=None):
    args = parse_args(argv)
    out = common.out_dir(args)
    gaits = QUICK_GAITS if args.quick else PAPER_GAITS
    params = convergence_params(args.n_arc, gaits)
    if args.quick:
        params = params[:-len(gaits)]
    solver = common.solver_for(args)
    duration = common.QUICK_DURATION_S if args.quick else None
    batch = common.run_batch(params, cycles=args.cycles, duration_s=duration, solver=solver,
                             arch=args.arch, chunk_size=common.chunk_size_for(args),
                             progress=not args.no_progress)
    table = convergence_table(batch.summary)
    csv_path = common.write_csv(table, out / "convergence.csv")
    png_path = plot_convergence(csv_path, out / "convergence.png")
    print(common.describe([csv_path, png_path]))
    return table
