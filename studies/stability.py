"""Numerical stability stress test (issue 5, design §6 "no NaN, no silent non-convergence, on
every stress case; failures isolated per instance").

    python -m studies stability [--quick] [--arch cpu|gpu] [--out results/] [--workers N]
                                [--dts-ms 0.5,1,2,5,10,20] [--stiffness 0.01,0.1,1,10,100]
                                [--alphas 0,0.8,1.5] [--added-mass 0,1,5] [--periods 0.3,3.15]
                                [--gaits A1,A1+...+A8,A1+A5] [--precisions f64,f32] [--cycles 2]

The stress grid (default): dt ∈ {0.5, 1, 2, 5, 10, 20} ms × stiffness factor ∈ {0.01, 0.1, 1,
10, 100} (youngs_modulus = factor × 5e6 Pa; E_limb/E stays 100, so limbs scale too) × α ∈ {0,
0.8, 1.5} × C_a ∈ {0, 1, 5} × period ∈ {0.3, 3.15} s × gaits {A1, all eight, A1+A5} × precision
{f64 (newton_tol 1e-10 m), f32 (newton_tol 1e-7 m)}, `--cycles` (2) cycles from rest each: 3,240
instances. One `simulate` batch per (precision, dt, period); other settings are the defaults
(implicit Euler, Newton Jacobian, max_newton 25, up to 4 substep halvings).

Per instance, node positions are recorded about every 0.06 s (a divisor of the run's step count
near 0.06 s / dt steps; the final shape is always a record) and checked:

- `max_strain`: max |ε| = | |x_j − x_i| / Δl̄ − 1 | over all edges and records; `max_strain_final`
  the same on the final shape;
- `limbs_cross`: two limb polylines (joint → tip, the `n_limb` LIMB edges of each limb) intersect
  (`segments_cross` between segments of different limbs: a proper crossing, or a collinear
  overlap; near-parallel segments are tested for collinear overlap, since their intersection
  parameters are rounding noise: opposite limbs of a symmetric gait are collinear), in any
  record;
  `limbs_cross_final` on the final shape;
- `arc_inverted`: an actuator arc's mean signed curvature (Σ κ_i Δl_i / Σ Δl_i over its interior
  ARC_BEND triplets, i.e. its total turning over its length) has the opposite sign to its rest
  value, in any record (the actuation only ever lowers |κ⁰| from 102 to ≈ 14 1/m, never through
  zero, so an inversion is never asked for); `arc_inverted_final` on the final shape;
- `sane` = finite positions and no crossing and no inversion in any record and max_strain ≤
  `STRAIN_LIMIT` (0.5: the linear rod model of design §2.2 means nothing past 50 % strain).

Records of a failed instance are NaN from its failure on; the checks use its finite records
(so max_strain of a failed instance is the largest before its failure).

`outcome`: `failed` (status newton_failed / non_finite), `insane` (status ok but not `sane`),
`retried-then-ok` (ok and sane after ≥ 1 substep retry), `ok` (ok, sane, no retry).

Writes
- `stability.csv`: one row per instance: stiffness_factor, dt_ms, precision, newton_tol, cycles,
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
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pandas as pd

import taichi_star
from taichi_star.geometry import ARC_BEND, LIMB, discrete_curvature
from taichi_star.params import SolverConfig, StarParams

from . import common

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
TOLERANCE = {"f64": 1e-10, "f32": 1e-7}
"""newton_tol per precision: the default, and the smallest f32 accepts (SolverConfig)."""
BASE_MODULUS = 5e6
"""youngs_modulus at stiffness factor 1 (the paper's E), Pa."""
CYCLES = 2.0

QUICK_DTS_MS = (1.0, 10.0)
QUICK_STIFFNESS = (1.0, 100.0)
QUICK_GAITS = ("A1",)
QUICK_DURATION_S = 0.05

RECORD_SPACING_S = 0.06
STRAIN_LIMIT = 0.5
"""|ε| above this is insane: the linear stretching energy of design §2.2 is a small-strain model."""

PAPER = {"stiffness_factor": 1.0, "alpha": 0.8, "added_mass_coeff": 1.0, "period": 3.15}
"""The paper's parameters within the grid (design §2)."""

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


# --------------------------------------------------------------------------- shape checks

def limb_polylines(topology) -> np.ndarray:
    """(8, n_limb + 1) node indices of each limb from its joint to its tip (LIMB edges)."""
    limb_edges = topology.edges[topology.edge_kind == LIMB]
    following = {}
    for a, b in limb_edges:
        following.setdefault(int(a), []).append(int(b))
        following.setdefault(int(b), []).append(int(a))
    lines = []
    for joint, tip in zip(topology.joints, topology.tips):
        line, previous = [int(joint)], None
        while line[-1] != int(tip):
            nxt = [n for n in following[line[-1]] if n != previous]
            if len(nxt) != 1:
                raise ValueError(f"limb from joint {joint} is not a chain to its tip {tip}")
            previous = line[-1]
            line.append(nxt[0])
        lines.append(line)
    return np.array(lines)


def _cross(a, b):
    """2-D cross product a × b over the last axis."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


PARALLEL_TOLERANCE = 1e-9
"""Segments whose directions differ by less than ~1e-9 rad are treated as parallel: the
intersection parameters of (near-)parallel segments are rounding noise (opposite limbs of a
symmetric shape are collinear, and a plain orientation test finds them 'crossing' by rounding)."""


def segments_cross(p, q, r, s) -> np.ndarray:
    """Segments p–q and r–s (arrays (..., 2)) -> (...) bool: they cross. Non-parallel segments
    cross where both intersection parameters lie strictly inside (0, 1) (touching at an end is
    not counted); (near-)parallel ones where they are collinear (distance ≤ 1e-9 of their
    length) and their extents along the line overlap with positive length."""
    d1, d2, offset = q - p, s - r, r - p
    scale = np.linalg.norm(d1, axis=-1) * np.linalg.norm(d2, axis=-1)
    denominator = _cross(d1, d2)
    parallel = ~(np.abs(denominator) > PARALLEL_TOLERANCE * scale)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = _cross(offset, d2) / denominator
        u = _cross(offset, d1) / denominator
        proper = (t > 0) & (t < 1) & (u > 0) & (u < 1)
        # parallel: collinear and overlapping along p–q
        length1 = np.linalg.norm(d1, axis=-1)
        distance = np.abs(_cross(offset, d1)) / length1
        along_r = (offset * d1).sum(-1) / length1
        along_s = ((s - p) * d1).sum(-1) / length1
        low, high = np.minimum(along_r, along_s), np.maximum(along_r, along_s)
        overlap = np.minimum(high, length1) - np.maximum(low, 0.0)
        collinear = (distance <= PARALLEL_TOLERANCE * length1) & (overlap > 0)
    return np.where(parallel, collinear, proper)


def limbs_cross(positions: np.ndarray, topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: some segment of one limb crosses a segment of another
    limb (`segments_cross`)."""
    lines = limb_polylines(topology)
    points = positions[..., lines, :]                   # (..., 8, L+1, 2)
    start, end = points[..., :-1, :], points[..., 1:, :]  # (..., 8, L, 2)
    n_limbs = lines.shape[0]
    first, second = np.triu_indices(n_limbs, k=1)
    # (..., pairs, L, 1, 2) against (..., pairs, 1, L, 2)
    hit = segments_cross(start[..., first, :, None, :], end[..., first, :, None, :],
                         start[..., second, None, :, :], end[..., second, None, :, :])
    return hit.any(axis=(-3, -2, -1))


def arc_mean_curvature(positions: np.ndarray, topology) -> np.ndarray:
    """positions (..., N, 2) -> (..., 8): each actuator arc's mean signed curvature, 1/m:
    Σ κ_i Δl_i / Σ Δl_i over its interior (ARC_BEND) triplets, Δl_i the rest Voronoi lengths."""
    arc = topology.triplet_kind == ARC_BEND
    tri = topology.triplets[arc]
    voronoi = topology.voronoi_length[arc]
    owner = topology.triplet_actuator[arc]
    kappa = discrete_curvature(positions[..., tri[:, 0], :], positions[..., tri[:, 1], :],
                               positions[..., tri[:, 2], :], voronoi)
    n_arcs = int(owner.max()) + 1
    weights = np.zeros((len(owner), n_arcs))
    weights[np.arange(len(owner)), owner] = voronoi
    return (kappa @ weights) / weights.sum(axis=0)


def arcs_inverted(positions: np.ndarray, topology) -> np.ndarray:
    """positions (..., N, 2) -> (...) bool: some arc's mean curvature has the opposite sign to
    its rest value (or is not finite)."""
    rest = np.sign(arc_mean_curvature(topology.rest_positions, topology))
    current = arc_mean_curvature(positions, topology)
    return (~(current * rest > 0)).any(axis=-1)


def edge_strain(positions: np.ndarray, topology) -> np.ndarray:
    """positions (..., N, 2) -> (..., E) ε = |x_j − x_i| / Δl̄ − 1."""
    edges = topology.edges
    length = np.linalg.norm(positions[..., edges[:, 1], :] - positions[..., edges[:, 0], :],
                            axis=-1)
    return length / topology.rest_length - 1.0


def shape_checks(shapes: np.ndarray, topology) -> pd.DataFrame:
    """shapes (R, B, N, 2) records of B instances (the last record is the final shape) ->
    one row per instance: max_strain, max_strain_final, limbs_cross, limbs_cross_final,
    arc_inverted, arc_inverted_final, finite, sane (see the module docstring)."""
    shapes = np.asarray(shapes, dtype=np.float64)
    n_records, batch = shapes.shape[:2]
    finite = np.isfinite(shapes).all(axis=(0, 2, 3))
    strain_max = np.full(batch, -np.inf)
    cross_any = np.zeros(batch, dtype=bool)
    inverted_any = np.zeros(batch, dtype=bool)
    # one record at a time keeps the pairwise segment test small; records of a failed instance
    # are NaN from its failure on: the checks use its finite records only
    for r in range(n_records):
        valid = np.isfinite(shapes[r]).all(axis=(1, 2))
        strain = np.abs(edge_strain(shapes[r], topology)).max(axis=-1)
        strain_max = np.where(valid, np.fmax(strain_max, strain), strain_max)
        cross_any |= limbs_cross(shapes[r], topology) & valid
        inverted_any |= arcs_inverted(shapes[r], topology) & valid
    final = shapes[-1]
    final_valid = np.isfinite(final).all(axis=(1, 2))
    table = pd.DataFrame({
        "max_strain": np.where(np.isfinite(strain_max), strain_max, np.nan),
        "max_strain_final": np.abs(edge_strain(final, topology)).max(axis=-1),
        "limbs_cross": cross_any,
        "limbs_cross_final": limbs_cross(final, topology) & final_valid,
        "arc_inverted": inverted_any,
        "arc_inverted_final": arcs_inverted(final, topology) & final_valid,
        "finite": finite,
    })
    table["sane"] = (finite & ~table["limbs_cross"] & ~table["arc_inverted"]
                     & (table["max_strain"] <= STRAIN_LIMIT))
    return table


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
                    except ValueError as error:
                        raise common.StudyArgumentError(f"invalid grid value: {error}") from None
                    factors.append(factor)
    return params, factors


def plan(args):
    """Validated batches: a list of dicts (precision, dt_s, period, duration_s, n_steps, params,
    factors, solver). Raises StudyArgumentError before any compute."""
    if args.dt is not None:
        raise common.StudyArgumentError("--dt: the stability grid sets the time steps; use "
                                        "--dts-ms")
    if args.workers < 1:
        raise common.StudyArgumentError(f"--workers must be >= 1, got {args.workers}")
    if args.workers > 1 and args.arch != "cpu":
        raise common.StudyArgumentError("--workers > 1 runs CPU processes; use --workers 1 "
                                        "with --arch gpu")
    common.check_positive(args.cycles, "--cycles")
    quick = args.quick
    dts = (common.parse_values(args.dts_ms, "--dts-ms") if args.dts_ms
           else list(QUICK_DTS_MS if quick else DTS_MS))
    stiffness = (common.parse_values(args.stiffness, "--stiffness") if args.stiffness
                 else list(QUICK_STIFFNESS if quick else STIFFNESS))
    alphas = (common.parse_values(args.alphas, "--alphas") if args.alphas
              else [PAPER["alpha"]] if quick else list(ALPHAS))
    added = (common.parse_values(args.added_mass, "--added-mass") if args.added_mass
             else [PAPER["added_mass_coeff"]] if quick else list(ADDED_MASS))
    periods = (common.parse_values(args.periods, "--periods") if args.periods
               else [PAPER["period"]] if quick else list(PERIODS))
    gaits = (common.resolve_gaits(args.gaits) if args.gaits
             else list(QUICK_GAITS if quick else GAITS))
    precisions = (common.parse_values(args.precisions, "--precisions", str) if args.precisions
                  else ["f64"] if quick else list(PRECISIONS))
    for name, values in (("--dts-ms", dts), ("--stiffness", stiffness)):
        if any(v <= 0 for v in values):
            raise common.StudyArgumentError(f"{name}: every value must be > 0, got {values}")
    for precision in precisions:
        if precision not in TOLERANCE:
            raise common.StudyArgumentError(f"--precisions: {precision!r} is not one of "
                                            f"{list(TOLERANCE)}")
    base = common.base_params(args)
    batches = []
    for precision in precisions:          # one precision after the other: one Taichi re-init
        for period in periods:
            params, factors = grid_params(gaits, stiffness, alphas, added, period, base)
            duration = QUICK_DURATION_S if quick else args.cycles * period
            for dt_ms in dts:
                dt = dt_ms * 1e-3
                try:
                    solver = SolverConfig(dt=dt, precision=precision,
                                          newton_tol=TOLERANCE[precision])
                except ValueError as error:
                    raise common.StudyArgumentError(f"--dts-ms: {error}") from None
                n_steps = int(round(duration / dt))
                if n_steps < 1 or abs(n_steps * dt - duration) > 1e-9 * max(1.0, duration):
                    raise common.StudyArgumentError(
                        f"--dts-ms: dt {dt_ms} ms does not divide the duration {duration:g} s "
                        f"(period {period:g} s)")
                batches.append(dict(precision=precision, dt_s=dt, period=period,
                                    duration_s=duration, n_steps=n_steps, params=params,
                                    factors=factors, solver=solver))
    return batches


def run_grid(batches, arch="cpu", workers=1, progress=True) -> pd.DataFrame:
    """Simulate every batch with shape records and return the per-instance table."""
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
        result = taichi_star.simulate(batch["params"], batch["duration_s"], solver=batch["solver"],
                                      arch=arch, record_every=stride, record_shapes=True,
                                      workers=workers)
        wall = time.perf_counter() - started
        checks = shape_checks(result.shapes, result.topology)
        summary = result.summary.reset_index(drop=True)
        front = pd.DataFrame({
            "instance": np.arange(first_instance, first_instance + len(summary)),
            "stiffness_factor": batch["factors"],
            "dt_ms": batch["dt_s"] * 1e3,
            "precision": batch["precision"],
            "newton_tol": batch["solver"].newton_tol,
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


KEY = ["gait", "stiffness_factor", "alpha", "added_mass_coeff", "period", "dt_ms"]


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
    reference = np.maximum(both["speed_mm_s_f64"].abs(), SPEED_FLOOR_MM_S)
    both["rel_speed_diff"] = np.where(stable, difference / reference, np.nan)
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
    plt = common.use_agg()
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
            tol = TOLERANCE.get(precision, math.nan)
            ax.set_title(f"{precision} (tol {tol:g} m), α = {alpha:g}", fontsize=8)
    fig.legend(handles=[Patch(color=OUTCOME_COLOURS[o], label=o) for o in OUTCOMES],
               loc="outside lower center", ncol=len(OUTCOMES), fontsize=7)
    runs = sorted(table["cycles"].round(6).unique())
    fig.suptitle(f"stability: {len(table)} instances, {', '.join(f'{c:g}' for c in runs)} "
                 f"cycle(s) from rest\ncell = C_a × period × gait, text = "
                 f"ok/retried/insane/failed", fontsize=8)
    path = Path(path)
    fig.savefig(path, dpi=130)
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
        for factor, part in f32.groupby("stiffness_factor"):
            lines.append(f"  x{factor:<6g} {int(part['n_f32_retried'].sum())} / "
                         f"{int(part['n_f64_retried'].sum())} of {int(part['n_pairs'].sum())}, "
                         f"worse {int(part['n_f32_worse'].sum())}, "
                         f"median {part['median_rel_speed_diff'].median():.2e}, "
                         f"max {part['max_rel_speed_diff'].max():.2e}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- CLI

def build_parser():
    parser = common.common_parser("stability", DESCRIPTION)
    parser.add_argument("--workers", type=int, default=1,
                        help="worker processes for simulate (CPU; default 1, use 2 on 2 cores)")
    parser.add_argument("--dts-ms", default=None,
                        help=f"time steps, ms (default {','.join(f'{d:g}' for d in DTS_MS)}; "
                             f"--quick {','.join(f'{d:g}' for d in QUICK_DTS_MS)})")
    parser.add_argument("--stiffness", default=None,
                        help=f"stiffness factors on E = 5 MPa (default "
                             f"{','.join(f'{s:g}' for s in STIFFNESS)})")
    parser.add_argument("--alphas", default=None, help="jet ratios (default 0,0.8,1.5)")
    parser.add_argument("--added-mass", default=None, help="C_a values (default 0,1,5)")
    parser.add_argument("--periods", default=None, help="periods, s (default 0.3,3.15)")
    parser.add_argument("--gaits", default=None,
                        help="gaits (default A1, A1+...+A8, A1+A5; --quick A1)")
    parser.add_argument("--precisions", default=None, help="f64,f32 (default both; --quick f64)")
    parser.add_argument("--cycles", type=float, default=CYCLES,
                        help=f"cycles from rest per instance (default {CYCLES:g}; --quick runs "
                             f"{QUICK_DURATION_S} s)")
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    batches = plan(args)
    out = common.out_dir(args)
    table = run_grid(batches, arch=args.arch, workers=args.workers,
                     progress=not args.no_progress)
    summary = outcome_summary(table)
    paper = paper_summary(table)
    f32 = f32_summary(table)
    paths = [common.write_csv(table, out / "stability.csv"),
             common.write_csv(summary, out / "stability_summary.csv")]
    if len(paper):
        paths.append(common.write_csv(paper, out / "stability_paper.csv"))
    if len(f32):
        paths.append(common.write_csv(f32, out / "stability_f32.csv"))
    paths.append(plot_maps(table, out / "stability.png"))
    text = report(table, summary, paper, f32)
    notes = out / "stability_notes.txt"
    notes.write_text(text + "\n")
    paths.append(notes)
    print(text)
    print(common.describe(paths))
    return table
