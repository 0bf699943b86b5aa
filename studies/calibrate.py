"""Calibration: fit up to two StarParams fields to the measured speeds of the five Fig. 4 gaits.

    python -m studies calibrate [--fit alpha=0.2:1.6:6] [--fit cylinder_drag=2:40:6:log]
                                [--refine 3] [--objective speed|signed] [--cycles 3]
                                [--arch cpu|gpu] [--out DIR] [--quick]
                                [--workers N | --scheduler tcp://HOST:PORT]

A coarse grid (the Cartesian product of the `--fit` ranges; `:log` ranges are refined in log
space) is followed by `--refine` rounds of a 3 × 3 (or 3-point) grid centred on the best point
so far, with half the previous spacing. Each round is one batch (every point × five gaits).
Objective: sum over the gaits of ((v_sim − v_exp)/v_exp)², v = |speed| over the cycles from rest
(`--objective signed` uses the signed speed against the paper's direction instead, so a wrong
direction costs more). Direction mismatches against the paper are counted for every point.

Writes `calibration.csv` (every point tried), `calibration_fit.csv` (the fitted values),
`calibration.png` (error surface and optimum), and `fig4c_calibrated.csv`: the Fig. 4c table
at the fitted values.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Dict, List, Sequence

import numpy as np
import pandas as pd

from taichi_star import StarParams
from taichi_star.batch import run_batch
from taichi_star.experiment import PAPER_GAITS, compare_with_experiment

from . import cli

DESCRIPTION = ("Fit up to two parameters (default alpha and cylinder_drag) to the experimental "
               "speeds of the five paper gaits: coarse grid, then local refinement.")

DEFAULT_FIT = ["alpha=0.2:1.6:6", "cylinder_drag=2:40:6:log"]
QUICK_FIT = ["alpha=0.4:1.2:2", "cylinder_drag=5:20:2:log"]
OBJECTIVES = ("speed", "signed")


def objective(table: pd.DataFrame, kind: str = "speed") -> float:
    """Sum of squared relative speed errors over the rows of a Fig. 4c table (inf if any
    simulation failed). kind "signed": the simulated signed speed is compared with the measured
    speed times +1 (paper forward) or −1 (paper reverse)."""
    if (table["status"] != "ok").any():
        return math.inf
    if kind == "signed":
        sign = np.where(table["paper_direction"] == "reverse", -1.0, 1.0)
        sim = table["sim_signed_speed_mm_s"].to_numpy(dtype=float)
        exp = sign * table["exp_speed_mm_s"].to_numpy(dtype=float)
    else:
        sim = table["sim_speed_mm_s"].to_numpy(dtype=float)
        exp = table["exp_speed_mm_s"].to_numpy(dtype=float)
    value = float(np.sum(((sim - exp) / exp) ** 2))
    return value if math.isfinite(value) else math.inf


class Axis:
    """One fitted parameter: name, bounds implied by the coarse range, log or linear spacing."""

    def __init__(self, name: str, text: str):
        self.name = name
        self.log = text.strip().lower().endswith(":log")
        self.values = cli.parse_values(text, f"--fit {name}", float)
        self.spacing = self._step(self.values)

    def _step(self, values):
        if len(values) < 2:
            return 0.0
        coords = np.log(values) if self.log else np.asarray(values)
        return float(abs(coords[1] - coords[0]))

    def around(self, centre: float, spacing: float) -> List[float]:
        if spacing == 0.0:
            return [centre]
        if self.log:
            coords = math.log(centre) + spacing * np.array([-1.0, 0.0, 1.0])
            return [float(v) for v in np.exp(coords)]
        return [float(v) for v in centre + spacing * np.array([-1.0, 0.0, 1.0])]


def parse_fit(items: Sequence[str]) -> List[Axis]:
    """`--fit NAME=RANGE` items -> Axis list (1 or 2; real-valued StarParams fields only)."""
    if len(items) > 2:
        raise cli.StudyArgumentError(f"--fit: at most two parameters, got {len(items)}")
    axes = []
    for item in items:
        if "=" not in item:
            raise cli.StudyArgumentError(
                f"--fit: expected NAME=RANGE (e.g. alpha=0.2:1.6:6), got {item!r}")
        name, text = item.split("=", 1)
        name = name.strip().replace("-", "_")
        if name == "gait":
            raise cli.StudyArgumentError("--fit gait: the gaits are fixed (the paper's five)")
        if cli.field_kind(name) is not float:
            raise cli.StudyArgumentError(f"--fit {name}: only real-valued parameters can be "
                                            f"fitted")
        if any(a.name == name for a in axes):
            raise cli.StudyArgumentError(f"--fit {name}: given twice")
        axes.append(Axis(name, text))
    return axes


def points_params(points: Sequence[Dict], base: StarParams):
    """All (point, gait) StarParams; raises StudyArgumentError on an invalid coarse point."""
    params = []
    for point in points:
        for gait in PAPER_GAITS:
            try:
                params.append(base.replace(gait=gait, **point))
            except (ValueError, TypeError) as error:
                raise cli.StudyArgumentError(f"--fit: invalid value: {error}") from None
    return params


def evaluate(points, base, run_kwargs, kind, round_index):
    """Simulate every point (one batch) and return one calibration row per point."""
    params = points_params(points, base)
    summary = run_batch(params, **run_kwargs).summary
    rows = []
    for index, point in enumerate(points):
        part = summary.iloc[index * len(PAPER_GAITS):(index + 1) * len(PAPER_GAITS)]
        table = compare_with_experiment(part)
        bad = table[table["status"] != "ok"]
        mismatched = table[(table["status"] == "ok") & ~table["direction_matches"]]
        row = {"round": round_index, **point,
               "objective": objective(table, kind),
               "n_direction_mismatches": int(len(mismatched)),
               "mismatched_gaits": " ".join(mismatched["gait"]),
               "status": "ok" if bad.empty else bad["status"].iloc[0]}
        for _, gait_row in table.iterrows():
            row[f"speed_{gait_row['gait']}"] = gait_row["sim_speed_mm_s"]
            row[f"signed_speed_{gait_row['gait']}"] = gait_row["sim_signed_speed_mm_s"]
        rows.append(row)
    return rows


def valid(point, base) -> bool:
    try:
        base.replace(**point)
        return True
    except (ValueError, TypeError):
        return False


def calibrate(axes: Sequence[Axis], base: StarParams = StarParams(), refine: int = 3,
              kind: str = "speed", **run_kwargs) -> pd.DataFrame:
    """Coarse grid then `refine` rounds of local 3-point-per-axis grids; returns every point
    tried (columns: round, the fitted parameters, objective, n_direction_mismatches,
    mismatched_gaits, status, speed_<gait>, signed_speed_<gait>)."""
    names = [a.name for a in axes]
    cli.param_product({a.name: a.values for a in axes}, base=base)  # validates the grid
    points = [dict(zip(names, combo)) for combo in
              itertools.product(*[a.values for a in axes])]
    rows = evaluate(points, base, run_kwargs, kind, 0)
    spacing = [a.spacing for a in axes]
    tried = {tuple(round(p[n], 12) for n in names) for p in points}
    for round_index in range(1, refine + 1):
        best = min(rows, key=lambda r: r["objective"])
        if not math.isfinite(best["objective"]):
            break
        spacing = [s / 2.0 for s in spacing]
        candidates = [{}]
        for axis, step in zip(axes, spacing):
            candidates = [dict(c, **{axis.name: v}) for c in candidates
                          for v in axis.around(best[axis.name], step)]
        candidates = [c for c in candidates if valid(c, base)
                      and tuple(round(c[n], 12) for n in names) not in tried]
        if not candidates:
            continue
        tried |= {tuple(round(c[n], 12) for n in names) for c in candidates}
        rows += evaluate(candidates, base, run_kwargs, kind, round_index)
    return pd.DataFrame(rows)


def best_point(table: pd.DataFrame, names: Sequence[str]) -> Dict:
    row = table.loc[table["objective"].astype(float).idxmin()]
    return {n: float(row[n]) for n in names}


def plot_calibration(csv_path, png_path, names: Sequence[str]):
    """Error surface from a calibration CSV: the coarse grid as filled contours of log10
    objective (two parameters) or a curve (one), every point tried as a dot, the optimum a star."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    finite = table[np.isfinite(table["objective"].astype(float))]
    best = finite.loc[finite["objective"].idxmin()] if len(finite) else None
    fig, ax = plt.subplots(figsize=(6.5, 5))
    if len(names) == 2:
        x, y = names
        coarse = finite[finite["round"] == 0]
        logx = (table[x] > 0).all() and table[x].max() / max(table[x].min(), 1e-300) >= 20
        logy = (table[y] > 0).all() and table[y].max() / max(table[y].min(), 1e-300) >= 20
        if len(coarse) >= 4 and coarse[x].nunique() >= 2 and coarse[y].nunique() >= 2:
            grid = coarse.pivot_table(index=y, columns=x, values="objective")
            contour = ax.contourf(grid.columns, grid.index, np.log10(grid.to_numpy()), levels=20,
                                  cmap="viridis")
            fig.colorbar(contour, ax=ax, label="log10 objective (coarse grid)")
        dots = ax.scatter(finite[x], finite[y], c=finite["round"], cmap="autumn", s=14,
                          edgecolors="k", linewidths=0.3, zorder=3)
        fig.colorbar(dots, ax=ax, label="round (0 = coarse grid)")
        if best is not None:
            ax.plot(best[x], best[y], "*", color="white", mec="k", ms=16, zorder=4)
        ax.set_xlabel(x)
        ax.set_ylabel(y)
        if logx:
            ax.set_xscale("log")
        if logy:
            ax.set_yscale("log")
    else:
        x = names[0]
        part = finite.sort_values(x)
        ax.semilogy(part[x], part["objective"], "o-", ms=3)
        if best is not None:
            ax.semilogy([best[x]], [best["objective"]], "*", ms=14, color="tab:red")
        ax.set_xlabel(x)
        ax.set_ylabel("objective")
    if best is not None:
        fitted = ", ".join(f"{n} = {best[n]:.4g}" for n in names)
        ax.set_title(f"calibration: best {fitted}\nobjective {best['objective']:.3g}; "
                     f"direction mismatches {int(best['n_direction_mismatches'])}", fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def build_parser():
    parser = cli.StudyParser("calibrate", DESCRIPTION)
    parser.add_argument("--fit", action="append", default=None, metavar="NAME=RANGE",
                        help="a StarParams field and its coarse range start:stop:n[:log] or list; "
                             "at most two (default: alpha=0.2:1.6:6 and "
                             "cylinder_drag=2:40:6:log)")
    parser.add_argument("--refine", type=int, default=3, quick=1,
                        help="local refinement rounds")
    parser.add_argument("--objective", choices=OBJECTIVES, default="speed",
                        help="speed: |speed| errors (default); signed: signed speed vs the "
                             "paper's direction")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    cli.add_execution_flags(parser)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    axes = parse_fit(args.fit if args.fit else (QUICK_FIT if args.quick else DEFAULT_FIT))
    if args.refine < 0:
        raise cli.StudyArgumentError(f"--refine must be >= 0, got {args.refine}")
    base = cli.base_params(args)
    clash = {a.name for a in axes} & {item.split("=", 1)[0].strip() for item in args.set}
    if clash:
        raise cli.StudyArgumentError(f"--set {sorted(clash)[0]}: fitted by the study")
    names = [a.name for a in axes]
    cli.param_product({a.name: a.values for a in axes}, base=base)  # validate before compute
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    with cli.executor(args) as executor:
        # a refinement round has 3^k points x 5 gaits; chunks sized so that it still feeds
        # every worker (the coarse round then simply has more chunks)
        per_round = 3 ** len(axes) * len(PAPER_GAITS)
        run_kwargs = dict(**cli.run_length(args), solver=solver, arch=args.arch,
                          progress=not args.no_progress, executor=executor,
                          chunk_size=cli.chunk_size(args, per_round, executor.n_workers))
        table = calibrate(axes, base=base, refine=args.refine, kind=args.objective, **run_kwargs)
        finite = table[np.isfinite(table["objective"].astype(float))]
        best = best_point(finite, names) if len(finite) else None
        fitted = (run_batch(points_params([best], base), **run_kwargs).summary
                  if best is not None else None)
    csv = out.write_csv(table, "calibration.csv")
    if best is None:
        print("calibration: every point failed; no fit")
        return table
    best_row = finite.loc[finite["objective"].idxmin()]
    fit = pd.DataFrame({"parameter": names, "value": [best[n] for n in names]})
    fit["objective"] = best_row["objective"]
    fit["objective_kind"] = args.objective
    fit["n_direction_mismatches"] = int(best_row["n_direction_mismatches"])
    fit["mismatched_gaits"] = best_row["mismatched_gaits"] if isinstance(
        best_row["mismatched_gaits"], str) else ""
    out.write_csv(fit, "calibration_fit.csv")
    table4c = compare_with_experiment(fitted)
    out.write_csv(table4c, "fig4c_calibrated.csv")
    out.wrote(plot_calibration(csv, out.path("calibration.png"), names))
    out.report()
    print("fitted: " + ", ".join(f"{n} = {best[n]:.6g}" for n in names)
          + f" (objective {best_row['objective']:.4g}, direction mismatches "
            f"{int(best_row['n_direction_mismatches'])})")
    still = table4c[~table4c["direction_matches"].astype(bool)]["gait"].tolist()
    print(table4c.to_string(index=False))
    print("gaits whose direction still disagrees with the paper: "
          + (", ".join(still) if still else "none"))
    return table
