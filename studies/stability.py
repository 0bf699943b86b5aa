"""Numerical stability stress test: no NaN, no silent non-convergence on any stress case, and
failures isolated per instance.

    python -m studies stability [--quick] [--arch cpu|gpu] [--out DIR] [--workers N]
                                [--dts-ms 0.5,1,2,5,10,20] [--stiffness 0.01,0.1,1,10,100]
                                [--alphas 0,0.8,1.5] [--added-mass 0,1,5] [--periods 0.3,3.15]
                                [--gaits A1,A1+...+A8,A1+A5] [--precisions f64,f32] [--cycles 2]

The stress grid (default): dt ∈ {0.5, 1, 2, 5, 10, 20} ms × stiffness factor ∈ {0.01, 0.1, 1,
10, 100} (youngs_modulus = factor × 5e6 Pa; E_limb/E stays 100, so limbs scale too) × α ∈ {0,
0.8, 1.5} × C_a ∈ {0, 1, 5} × period ∈ {0.3, 3.15} s × gaits {A1, all eight, A1+A5} × precision
{f64 (newton_tol 1e-10 m), f32 (newton_tol 1e-7 m)}, `--cycles` (2) cycles from rest each: 3,240
instances. One `run_batch` batch per (precision, dt, period), in chunks of --chunk-size (by
default fewer, to give every one of --workers about four; the results are the same bit for bit);
other settings are the defaults (implicit Euler, Newton Jacobian, max_newton 25, up to 4 substep
halvings). The whole grid's robot-steps are refused or estimated before any instance is built.

Per instance, node positions are recorded about every 0.06 s (a divisor of the run's step count
near 0.06 s / dt steps; the final shape is always a record) and checked with
`taichi_star.metrics.shape_checks`: max_strain (and _final), limbs_cross (and _final),
arc_inverted (and _final), finite, sane (finite, no crossing, no inversion, |ε| ≤ 0.5). Records
of a failed instance are NaN from its failure on; the checks use its finite records.

`outcome`: `failed` (status newton_failed / non_finite), `insane` (status ok but not `sane`),
`retried-then-ok` (ok and sane after ≥ 1 substep retry), `ok` (ok, sane, no retry).

Writes
- `stability.csv`: one row per instance: stiffness_factor, dt_ms, precision, newton_tol_m, cycles,
  duration_s, every StarParams field, the simulate summary (speeds, Newton statistics,
  substep_retries, status, failure_time_s), the checks above and `outcome`;
- `stability_summary.csv`: outcome counts (n_ok, n_retried_then_ok, n_insane, n_failed, n_total,
  stable_fraction = (ok + retried-then-ok) / total) for the whole grid (scope "all"), per
  precision, per precision × dt, and per precision × dt × stiffness factor;
- `stability_paper.csv`: at the paper's parameters (stiffness ×1, α 0.8, C_a 1, period 3.15 s),
  per gait and precision: the outcome at each dt, the largest dt with outcome ok / stable (ok or
  retried-then-ok), and the largest dt up to which every dt is stable; and the relative
  difference of the f32 speed from the f64 speed at the same parameters and dt;
- `stability_f32.csv`: f32 against f64 at identical parameters, per dt × stiffness factor:
  counts of cells where f32 is worse (f64 stable, f32 not) or retried, the median and max
  relative speed difference |v32 − v64| / max(|v64|, 0.01 mm/s) where both are stable (the
  floor: the symmetric gaits do not move), and `f32_breaks_down` (see F32_SPEED_LIMIT);
- `stability.png`: stable-region maps, dt against stiffness factor, one panel per precision × α,
  colour = the outcome colours mixed by their fractions among the cell's instances (C_a ×
  period × gait), text = counts ok / retried / insane / failed;
- `stability_notes.txt`: the printed summary.

A grid without the paper's parameters, or of one precision, has no rows for
`stability_paper.csv` or `stability_f32.csv`: that file is not written, and an earlier run's
left in --out is removed with its sidecar.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star import (NEWTON_TOL_DEFAULTS, SOLVER_RANGES, STAR_RANGES, SolverConfig,
                         StarParams, allowed_values)
from taichi_star.batch import DEFAULT_CHUNK_SIZE, run_batch, write_atomic
from taichi_star import metrics
from taichi_star.metrics import shape_checks
from taichi_star.timegrid import whole_steps

from . import cli

DESCRIPTION = ("Numerical stability stress grid: dt x stiffness x alpha x C_a x period x gait x "
               "precision; status, retries, strain and shape sanity per instance; stable-region "
               "maps.")

DTS_MS = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0)
STIFFNESS = (0.01, 0.1, 1.0, 10.0, 100.0)
ALPHAS = (0.0, 0.8, 1.5)
ADDED_MASS = (0.0, 1.0, 5.0)
PERIODS = (0.3, 3.15)
GAITS = ("A1", "A1+A2+A3+A4+A5+A6+A7+A8", "A1+A5")
PRECISIONS = ("f64", "f32")
BASE_MODULUS = 5e6
"""youngs_modulus at stiffness factor 1 (the paper's E), Pa."""
CYCLES = 2.0

QUICK_DTS_MS = (1.0, 10.0)
QUICK_STIFFNESS = (1.0, 100.0)
QUICK_GAITS = ("A1",)
QUICK_DURATION_S = 0.05

RECORD_SPACING_S = 0.06

PAPER_MODEL = StarParams.preset("paper")
PAPER = {"stiffness_factor": 1.0, "alpha": PAPER_MODEL.alpha,
         "added_mass_coeff": PAPER_MODEL.added_mass_coeff, "period_s": PAPER_MODEL.period}
"""The paper's parameters within the grid (its model's stiffness: a factor of 1)."""

SPEED_FLOOR_MM_S = 0.01
"""Floor of the reference speed in f32-vs-f64 relative differences: the symmetric gaits (A1+A5,
all eight) do not move (f64 speeds ~1e-13 mm/s), and 0.01 mm/s is far below any speed the studies
report (the slowest measured gait swims 0.43 mm/s)."""

F32_SPEED_LIMIT = 0.1
"""A dt × stiffness cell where f32 is unstable where f64 is not, needs substep retries that f64
does not, or whose median relative speed difference from f64 exceeds 10 % is where f32 "breaks
down" (`f32_breaks_down` in stability_f32.csv)."""

OUTCOMES = ("ok", "retried-then-ok", "insane", "failed")
STABLE = ("ok", "retried-then-ok")


# --------------------------------------------------------------------------- outcomes

def classify(status, substep_retries, sane) -> np.ndarray:
    """Outcome per instance: failed (status not ok) > insane > retried-then-ok > ok."""
    status = np.asarray(status)
    retries = np.asarray(substep_retries)
    sane = np.asarray(sane, dtype=bool)
    return np.where(status != "ok", "failed",
                    np.where(~sane, "insane", np.where(retries > 0, "retried-then-ok", "ok")))


# --------------------------------------------------------------------------- grid and running

def record_stride(n_steps: int, dt: float, spacing: float = RECORD_SPACING_S) -> int:
    """The largest divisor of n_steps not above round(spacing / dt) (at least 1), so the
    records are about `spacing` apart and the last one is the final shape."""
    target = max(1, int(round(spacing / dt)))
    return max(k for k in range(1, min(target, n_steps) + 1) if n_steps % k == 0)


def grid_params(gaits, stiffness, alphas, added_mass, period, base: StarParams):
    """(StarParams list, stiffness factor list) for one period: gait × stiffness × α × C_a."""
    params, factors = [], []
    for gait in gaits:
        for factor in stiffness:
            for alpha in alphas:
                for ca in added_mass:
                    try:
                        params.append(base.replace(gait=gait, youngs_modulus=factor * BASE_MODULUS,
                                                   alpha=alpha, added_mass_coeff=ca, period=period))
                    except ValueError as error:  # values that do not fit together
                        raise cli.StudyArgumentError(f"--gaits, --stiffness, --alphas, "
                                                     f"--added-mass, --periods together: "
                                                     f"{error}") from None
                    factors.append(factor)
    return params, factors


def check_step_and_stiffness_values(dts_ms, stiffness):
    """StudyArgumentError naming the flag, its range in the flag's own unit and the first value
    out of it: --dts-ms in ms (SolverConfig's dt range said "in (0, 0.05], got 1.0" for 1000
    ms), --stiffness as a factor on BASE_MODULUS (youngs_modulus's range said Pa)."""
    longest_ms = 1e3 * SOLVER_RANGES["dt"][1]
    # the values to 10 digits: 2000.0001 shown as "2000" would read as inside the range
    for dt_ms in dts_ms:
        if not 0 < dt_ms <= longest_ms:
            raise cli.StudyArgumentError(f"--dts-ms: every value must be in (0, {longest_ms:g}] "
                                         f"ms, got {dt_ms:.10g}")
    # the factor's range: youngs_modulus's declared one over the modulus at factor 1
    lowest, highest, lowest_included = STAR_RANGES["youngs_modulus"]
    lowest, highest = lowest / BASE_MODULUS, highest / BASE_MODULUS
    for factor in stiffness:
        above_lowest = factor >= lowest if lowest_included else factor > lowest
        if not (above_lowest and factor <= highest):
            raise cli.StudyArgumentError(
                f"--stiffness: every factor must be in {'[' if lowest_included else '('}"
                f"{lowest:g}, {highest:g}] (youngs_modulus = factor × {BASE_MODULUS:g} Pa must "
                f"be in {allowed_values('youngs_modulus')} Pa), got {factor:.10g}")


def plan(args):
    """Validated batches: a list of dicts (precision, dt_s, period, duration_s, n_steps, params,
    factors, solver, and base: the model the grid's values are set on). Raises
    StudyArgumentError before any compute, the whole grid's robot-steps refused or estimated
    before any instance is built."""
    quick = args.quick
    dts = cli.parse_values(args.dts_ms, "--dts-ms")
    stiffness = cli.parse_values(args.stiffness, "--stiffness")
    alphas = cli.parse_values(args.alphas, "--alphas")
    added = cli.parse_values(args.added_mass, "--added-mass")
    periods = cli.parse_values(args.periods, "--periods")
    gaits = cli.resolve_gaits(args.gaits)
    precisions = cli.parse_values(args.precisions, "--precisions", str)
    check_step_and_stiffness_values(dts, stiffness)
    for precision in precisions:
        if precision not in NEWTON_TOL_DEFAULTS:
            raise cli.StudyArgumentError(f"--precisions: {precision!r} is not one of "
                                            f"{list(NEWTON_TOL_DEFAULTS)}")
    # counted before any instance is built (a grid of three million was built for a minute)
    axes = {"--dts-ms": dts, "--stiffness": stiffness, "--alphas": alphas, "--added-mass": added,
            "--periods": periods, "--gaits": gaits, "--precisions": precisions}
    grid_text = " × ".join(f"{flag} {len(values)}" for flag, values in axes.items())
    cli.check_instances(math.prod(len(values) for values in axes.values()), grid_text)
    runs = []
    for precision in precisions:          # one precision after the other: one Taichi re-init
        for period in periods:
            duration = QUICK_DURATION_S if quick else args.cycles * period
            length = (f"--quick ({duration:g} s)" if quick
                      else f"--cycles {args.cycles:g} ({duration:.3g} s)")
            for dt_ms in dts:
                dt = dt_ms * 1e-3
                cli.check_length(length, duration, dt, "dt (--dts-ms)")
                try:
                    solver = SolverConfig(dt=dt, precision=precision)
                except ValueError as error:
                    raise cli.StudyArgumentError(f"--dts-ms: {error}") from None
                n_steps = whole_steps(duration, dt)
                if not n_steps:
                    raise cli.StudyArgumentError(
                        f"--dts-ms: dt {dt_ms} ms does not divide the duration {duration:g} s "
                        f"(period {period:g} s)")
                runs.append(dict(precision=precision, dt_s=dt, period=period,
                                 duration_s=duration, n_steps=n_steps, solver=solver))
    # every batch's steps checked above; the grid's robot-steps, all batches together, refused
    # or estimated here (each batch stayed under the warning: --cycles 10000 of the default
    # grid, 3.6e10 robot-steps, started without a word; an audit, 2026-12)
    per_batch = len(gaits) * len(stiffness) * len(alphas) * len(added)
    grid_length = (f"--quick ({QUICK_DURATION_S:g} s)" if quick
                   else f"--cycles {args.cycles:g} of each period")
    field_axes = {"gait": gaits, "youngs_modulus": [f * BASE_MODULUS for f in stiffness],
                  "alpha": alphas, "added_mass_coeff": added, "period": periods}
    base = cli.base_params(args, field_axes)
    cli.check_robot_steps(f"the grid of {per_batch * len(runs):,} instances ({grid_text}) for "
                          f"{grid_length}", per_batch * sum(run["n_steps"] for run in runs),
                          cli.work_arch(args), base.n_nodes)
    # each value on its own, named by its flag (the grid's refusal named none)
    cli.check_axis_values(
        field_axes, base,
        {"gait": "--gaits", "youngs_modulus": "--stiffness", "alpha": "--alphas",
         "added_mass_coeff": "--added-mass", "period": "--periods"})
    grids = {period: grid_params(gaits, stiffness, alphas, added, period, base)
             for period in periods}
    return [dict(run, params=grids[run["period"]][0], factors=grids[run["period"]][1], base=base)
            for run in runs]


def run_grid(batches, arch="cpu", executor=None, chunk_size=DEFAULT_CHUNK_SIZE,
             progress=True) -> pd.DataFrame:
    """Simulate every batch with shape records, in chunks of `chunk_size` instances, and
    return the per-instance table (bitwise the same for any chunking)."""
    total = sum(len(b["params"]) * b["n_steps"] for b in batches)
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=total, unit="robot-step", unit_scale=True, desc="stability")
    tables = []
    first_instance = 0
    for batch in batches:
        if bar is not None:
            bar.set_postfix_str(f"{batch['precision']} dt {batch['dt_s'] * 1e3:g} ms "
                                f"T {batch['period']:g} s")
        stride = record_stride(batch["n_steps"], batch["dt_s"])
        started = time.perf_counter()
        result = run_batch(batch["params"], batch["duration_s"], solver=batch["solver"],
                           arch=arch, record_interval_s=stride * batch["dt_s"],
                           record_shapes=True, executor=executor,
                           chunk_size=chunk_size,
                           progress=False)  # the grid's own bar counts the robot-steps
        wall = time.perf_counter() - started
        checks = shape_checks(result.shapes, result.topology)
        # the checks over every record replace the summary's final-shape ones
        summary = result.summary.drop(columns=["instance", "duration_s", "max_strain",
                                               "shape_sane"])
        front = pd.DataFrame({
            "instance": np.arange(first_instance, first_instance + len(summary)),
            "stiffness_factor": batch["factors"],
            "dt_ms": batch["dt_s"] * 1e3,
            "precision": batch["precision"],
            "newton_tol_m": batch["solver"].newton_tol,
            "cycles": batch["duration_s"] / batch["period"],
            "duration_s": batch["duration_s"],
            "n_steps": batch["n_steps"],
            "record_every_steps": stride,
            "batch_wall_s": wall,
        })
        table = pd.concat([front, summary, checks], axis=1)
        table["outcome"] = classify(table["status"], table["substep_retries"], table["sane"])
        tables.append(table)
        first_instance += len(summary)
        if bar is not None:
            bar.update(len(batch["params"]) * batch["n_steps"])
    if bar is not None:
        bar.close()
    return pd.concat(tables, ignore_index=True)


# --------------------------------------------------------------------------- summaries

def _counts(frame: pd.DataFrame) -> dict:
    counts = frame["outcome"].value_counts()
    row = {f"n_{name.replace('-', '_')}": int(counts.get(name, 0)) for name in OUTCOMES}
    row["n_total"] = len(frame)
    row["stable_fraction"] = (row["n_ok"] + row["n_retried_then_ok"]) / max(len(frame), 1)
    return row


def outcome_summary(table: pd.DataFrame) -> pd.DataFrame:
    """Outcome counts for the whole grid, per precision, per precision × dt, and per
    precision × dt × stiffness factor."""
    rows = [{"scope": "all", "precision": "all", "dt_ms": np.nan, "stiffness_factor": np.nan,
             **_counts(table)}]
    for precision, part in table.groupby("precision", sort=False):
        rows.append({"scope": "precision", "precision": precision, "dt_ms": np.nan,
                     "stiffness_factor": np.nan, **_counts(part)})
    for (precision, dt), part in table.groupby(["precision", "dt_ms"], sort=False):
        rows.append({"scope": "precision x dt", "precision": precision, "dt_ms": dt,
                     "stiffness_factor": np.nan, **_counts(part)})
    for (precision, dt, factor), part in table.groupby(["precision", "dt_ms", "stiffness_factor"],
                                                       sort=False):
        rows.append({"scope": "precision x dt x stiffness", "precision": precision, "dt_ms": dt,
                     "stiffness_factor": factor, **_counts(part)})
    return pd.DataFrame(rows)


KEY = ["gait", "stiffness_factor", "alpha", "added_mass_coeff", "period_s", "dt_ms"]


def _speed_difference(table: pd.DataFrame) -> pd.DataFrame:
    """f32 rows joined with their f64 twins: outcome_f32/f64, speed_f32/f64, speed_diff_mm_s
    = |speed f32 − speed f64| and rel_speed_diff = speed_diff / max(|speed f64|, SPEED_FLOOR)
    where both are stable, NaN otherwise."""
    columns = KEY + ["outcome", "speed_mm_s"]
    f64 = table[table["precision"] == "f64"][columns]
    f32 = table[table["precision"] == "f32"][columns]
    both = f32.merge(f64, on=KEY, suffixes=("_f32", "_f64"))
    stable = both["outcome_f32"].isin(STABLE) & both["outcome_f64"].isin(STABLE)
    difference = (both["speed_mm_s_f32"] - both["speed_mm_s_f64"]).abs()
    both["speed_diff_mm_s"] = np.where(stable, difference, np.nan)
    relative = metrics.speed_error(both["speed_mm_s_f32"], both["speed_mm_s_f64"],
                                   floor_mm_s=SPEED_FLOOR_MM_S)
    both["rel_speed_diff"] = np.where(stable, relative, np.nan)
    return both


def paper_summary(table: pd.DataFrame) -> pd.DataFrame:
    """At the paper's parameters, per gait × precision: outcome at each dt and the largest
    stable dts (module docstring)."""
    selection = table
    for name, value in PAPER.items():
        selection = selection[np.isclose(selection[name], value)]
    if selection.empty:
        return pd.DataFrame()
    differences = _speed_difference(selection) if selection["precision"].nunique() > 1 else None
    rows = []
    for (gait, precision), part in selection.groupby(["gait", "precision"], sort=False):
        part = part.sort_values("dt_ms")
        dts = part["dt_ms"].to_numpy()
        outcome = part["outcome"].to_numpy()
        stable = np.isin(outcome, STABLE)
        ok = outcome == "ok"
        prefix = np.cumprod(stable).astype(bool)
        row = {"gait": gait, "precision": precision,
               "largest_ok_dt_ms": dts[ok].max() if ok.any() else np.nan,
               "largest_stable_dt_ms": dts[stable].max() if stable.any() else np.nan,
               "stable_up_to_dt_ms": dts[prefix].max() if prefix.any() else np.nan}
        for dt, result, retries, speed in zip(dts, outcome, part["substep_retries"],
                                              part["speed_mm_s"]):
            row[f"outcome_dt_{dt:g}ms"] = result
            row[f"retries_dt_{dt:g}ms"] = int(retries)
            row[f"speed_mm_s_dt_{dt:g}ms"] = speed
        if differences is not None and precision == "f32":
            mine = differences[differences["gait"] == gait]
            for dt, diff in zip(mine["dt_ms"], mine["rel_speed_diff"]):
                row[f"f32_rel_speed_diff_dt_{dt:g}ms"] = diff
        rows.append(row)
    return pd.DataFrame(rows)


def f32_summary(table: pd.DataFrame) -> pd.DataFrame:
    """f32 against f64 at identical parameters, per dt × stiffness factor."""
    if set(table["precision"]) != {"f64", "f32"}:
        return pd.DataFrame()
    both = _speed_difference(table)
    rows = []
    for (dt, factor), part in both.groupby(["dt_ms", "stiffness_factor"]):
        stable64 = part["outcome_f64"].isin(STABLE)
        stable32 = part["outcome_f32"].isin(STABLE)
        diff = part["rel_speed_diff"].dropna()
        absolute = part["speed_diff_mm_s"].dropna()
        rows.append({"dt_ms": dt, "stiffness_factor": factor, "n_pairs": len(part),
                     "n_f64_stable": int(stable64.sum()), "n_f32_stable": int(stable32.sum()),
                     "n_f32_worse": int((stable64 & ~stable32).sum()),
                     "n_f32_better": int((~stable64 & stable32).sum()),
                     "n_f32_retried": int((part["outcome_f32"] == "retried-then-ok").sum()),
                     "n_f64_retried": int((part["outcome_f64"] == "retried-then-ok").sum()),
                     "n_both_stable": len(diff),
                     "median_rel_speed_diff": diff.median() if len(diff) else np.nan,
                     "max_rel_speed_diff": diff.max() if len(diff) else np.nan,
                     "max_speed_diff_mm_s": absolute.max() if len(absolute) else np.nan})
    table = pd.DataFrame(rows)
    table["f32_breaks_down"] = ((table["n_f32_worse"] > 0)
                                | (table["n_f32_retried"] > table["n_f64_retried"])
                                | (table["median_rel_speed_diff"] > F32_SPEED_LIMIT))
    return table


OUTCOME_COLOURS = {"ok": "#1a9850", "retried-then-ok": "#4575b4", "insane": "#fdae61",
                   "failed": "#d73027"}


def plot_maps(table: pd.DataFrame, path) -> Path:
    """Stable-region maps: one panel per precision × α, dt (x) against stiffness factor (y);
    each cell's colour is the mix of the outcome colours weighted by their fractions among the
    cell's instances (C_a × period × gait), its text the counts ok/retried/insane/failed."""
    plt = cli.use_agg()
    from matplotlib.colors import to_rgb
    from matplotlib.patches import Patch
    precisions = list(dict.fromkeys(table["precision"]))
    alphas = sorted(table["alpha"].unique())
    dts = sorted(table["dt_ms"].unique())
    factors = sorted(table["stiffness_factor"].unique())
    colours = np.array([to_rgb(OUTCOME_COLOURS[o]) for o in OUTCOMES])
    fig, axes = plt.subplots(len(precisions), len(alphas), squeeze=False, sharex=True,
                             sharey=True, constrained_layout=True,
                             figsize=(1.5 + 0.62 * len(dts) * len(alphas),
                                      1.4 + 0.5 * len(factors) * len(precisions)))
    for i, precision in enumerate(precisions):
        for j, alpha in enumerate(alphas):
            ax = axes[i, j]
            part = table[(table["precision"] == precision) & np.isclose(table["alpha"], alpha)]
            image = np.ones((len(factors), len(dts), 3))
            for (dt, factor), cell in part.groupby(["dt_ms", "stiffness_factor"]):
                y, x = factors.index(factor), dts.index(dt)
                counts = cell["outcome"].value_counts()
                numbers = np.array([counts.get(o, 0) for o in OUTCOMES], dtype=float)
                image[y, x] = numbers @ colours / numbers.sum()
                ax.text(x, y, "/".join(str(int(n)) for n in numbers), ha="center",
                        va="center", fontsize=5.5)
            ax.imshow(image, origin="lower", aspect="auto")
            ax.set_xticks(range(len(dts)), [f"{d:g}" for d in dts])
            ax.set_yticks(range(len(factors)), [f"{f:g}" for f in factors])
            if i == len(precisions) - 1:
                ax.set_xlabel("dt (ms)")
            if j == 0:
                ax.set_ylabel("stiffness ×\n(E / 5 MPa)")
            tol = NEWTON_TOL_DEFAULTS.get(precision, math.nan)
            ax.set_title(f"{precision} (tol {tol:g} m), α = {alpha:g}", fontsize=8)
    fig.legend(handles=[Patch(color=OUTCOME_COLOURS[o], label=o) for o in OUTCOMES],
               loc="outside lower center", ncol=len(OUTCOMES), fontsize=7)
    runs = sorted(table["cycles"].round(6).unique())
    fig.suptitle(f"stability: {len(table)} instances, {', '.join(f'{c:g}' for c in runs)} "
                 f"cycle(s) from rest\ncell = C_a × period × gait, text = "
                 f"ok/retried/insane/failed", fontsize=8)
    path = Path(path)
    cli.write_figure(fig, path, dpi=130)
    plt.close(fig)
    return path


def report(table, summary, paper, f32) -> str:
    """A plain-text summary of the run (printed and written to stability_notes.txt)."""
    lines = []
    totals = summary[summary["scope"].isin(["all", "precision"])]
    lines.append("outcome counts (ok / retried-then-ok / insane / failed of total):")
    for _, row in totals.iterrows():
        lines.append(f"  {row['precision']:>4}: {row['n_ok']} / {row['n_retried_then_ok']} / "
                     f"{row['n_insane']} / {row['n_failed']} of {row['n_total']}")
    statuses = table["status"].value_counts().to_dict()
    lines.append(f"simulate status counts: {statuses}")
    if len(paper):
        lines.append("paper parameters (stiffness x1, alpha 0.8, C_a 1, period 3.15 s): largest "
                     "dt (ms) ok / stable / stable at every dt up to it:")
        for _, row in paper.iterrows():
            lines.append(f"  {row['precision']} {row['gait']:<24} {row['largest_ok_dt_ms']:g} / "
                         f"{row['largest_stable_dt_ms']:g} / {row['stable_up_to_dt_ms']:g}")
    if len(f32):
        worse = f32[f32["n_f32_worse"] > 0]
        lines.append(f"f32 vs f64 at identical parameters: f32 unstable where f64 is stable in "
                     f"{int(f32['n_f32_worse'].sum())} of {int(f32['n_pairs'].sum())} pairs; "
                     f"f32 stable where f64 is not in {int(f32['n_f32_better'].sum())}")
        for _, row in worse.iterrows():
            lines.append(f"  dt {row['dt_ms']:g} ms, stiffness x{row['stiffness_factor']:g}: "
                         f"{row['n_f32_worse']} of {row['n_pairs']}")
        broken = f32[f32["f32_breaks_down"]]
        lines.append(f"f32 breaks down (unstable or retried where f64 is not, or median speed "
                     f"difference > {F32_SPEED_LIMIT:.0%}) in {len(broken)} of {len(f32)} "
                     f"dt x stiffness cells:")
        for factor, part in broken.groupby("stiffness_factor"):
            lines.append(f"  stiffness x{factor:g}: dt "
                         + ", ".join(f"{dt:g}" for dt in part["dt_ms"]) + " ms")
        lines.append("f32 by stiffness factor (over all dt): retried-then-ok f32 / f64, f32 "
                     "unstable where f64 stable, median and max |speed f32 - f64| / max(|speed "
                     f"f64|, {SPEED_FLOOR_MM_S} mm/s) where both stable:")
        # the median over the factor's pairs themselves (a median of the cells' medians
        # overstated it 1.4x and 2.4x at 10x and 100x the stiffness; an audit, 2026-12)
        pairs = _speed_difference(table).groupby("stiffness_factor")["rel_speed_diff"]
        for factor, part in f32.groupby("stiffness_factor"):
            lines.append(f"  x{factor:<6g} {int(part['n_f32_retried'].sum())} / "
                         f"{int(part['n_f64_retried'].sum())} of {int(part['n_pairs'].sum())}, "
                         f"worse {int(part['n_f32_worse'].sum())}, "
                         f"median {pairs.get_group(factor).median():.2e}, "
                         f"max {part['max_rel_speed_diff'].max():.2e}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- CLI

def numbers(values) -> str:
    """A flag's text for a tuple of numbers: "0.5,1,2"."""
    return ",".join(f"{v:g}" for v in values)


def build_parser():
    parser = cli.StudyParser("stability", DESCRIPTION)
    parser.add_argument("--dts-ms", default=numbers(DTS_MS), quick=numbers(QUICK_DTS_MS),
                        help="time steps, ms")
    parser.add_argument("--stiffness", default=numbers(STIFFNESS), quick=numbers(QUICK_STIFFNESS),
                        help="stiffness factors on E = 5 MPa")
    parser.add_argument("--alphas", default=numbers(ALPHAS), quick=numbers([PAPER["alpha"]]),
                        help="jet ratios")
    parser.add_argument("--added-mass", default=numbers(ADDED_MASS),
                        quick=numbers([PAPER["added_mass_coeff"]]), help="C_a values")
    parser.add_argument("--periods", default=numbers(PERIODS), quick=numbers([PAPER["period_s"]]),
                        help="periods, s")
    parser.add_argument("--gaits", default=",".join(GAITS), quick=",".join(QUICK_GAITS),
                        help=cli.GAITS_HELP)
    parser.add_argument("--precisions", default=",".join(PRECISIONS), quick="f64",
                        help="f64 and/or f32")
    cli.add_model_flags(parser, fixed=("gait", "youngs_modulus", "alpha", "added_mass_coeff",
                                       "period"))
    cli.add_cycles_flag(parser, default=CYCLES, quick_s=QUICK_DURATION_S)
    cli.add_execution_flags(parser)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    batches = plan(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset,
                                              "params": batches[0]["base"]},
                     solver={precision: {"newton_tol": tolerance} for precision, tolerance
                             in NEWTON_TOL_DEFAULTS.items()})
    # the plan told the grid's hours (`plan`): its batches' own estimates would repeat them
    with cli.executor(args, out) as executor, cli.batch_work_told():
        # every batch has as many instances; cut to about four chunks per worker (--chunk-size's
        # help): a batch was one chunk, one worker busy and the others idle (an audit, 2026-12)
        chunk_size = cli.chunk_size(args, len(batches[0]["params"]), executor.n_workers)
        table = run_grid(batches, arch=args.arch, executor=executor, chunk_size=chunk_size,
                         progress=not args.no_progress)
    summary = outcome_summary(table)
    paper = paper_summary(table)
    f32 = f32_summary(table)
    csv = out.write_csv(table, "stability.csv")
    out.write_csv(summary, "stability_summary.csv")
    for companion, name in ((paper, "stability_paper.csv"), (f32, "stability_f32.csv")):
        if len(companion):
            out.write_csv(companion, name)
        else:
            out.remove_earlier(name)
    # drawn from the table as written, so that the CSV redraws it
    out.wrote(plot_maps(pd.read_csv(csv), out.path("stability.png")))
    text = report(table, summary, paper, f32)
    notes = out.path("stability_notes.txt")
    write_atomic(notes, (text + "\n").encode(), failure=lambda reason: cli.StudyOutputError(
        f"--out {out.folder}: {reason}; the files written before are intact"))
    out.wrote(notes)
    print(text)
    out.report()
    return table
