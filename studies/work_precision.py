"""Run time against error: the five paper gaits' speeds over 3 cycles from rest for
time step, precision, Newton tolerance, discretisation and integrator, against a reference run.

    python -m studies work_precision [--arch cpu|gpu] [--out DIR] [--quick]
                                     [--gaits paper|A1,A1+A2,...] [--cycles 3] [--no-progress]

Reference: h = 0.125 ms, f64, newton_tol 1e-12 m, 2× the paper's discretisation (n_arc 36,
n_limb 12), BDF2. Configurations (not the full Cartesian product): one
axis at a time around the default (h = 1 ms, f64, tol 1e-10 m, 1× = n_arc 18 / n_limb 6, implicit
Euler), i.e. f32 (tol 1e-7 and 1e-6 m: f32 cannot resolve less), tol 1e-6 and 1e-8 m, ½× (n_arc
9, n_limb 3); and the h axis h ∈ {0.25, 0.5, 1, 2, 4, 8} ms for every integrator, both at 1× and at
2× (the reference's discretisation, where the error is the time-stepping and solver error alone).
Each configuration is one `simulate` batch of the gaits; its run time is the wall time of that
call after a one-step call has compiled its kernels. With a handful of instances the batch
cannot fill many cores: these run times rank the settings, `studies bench` measures throughput.

Error of a gait: |speed − reference speed| / |reference speed| of `speed_mm_s` (3 cycles from
rest); a configuration's error is the largest over the gaits (NaN if an instance
failed). h values that do not divide the duration simulate the nearest whole number of steps.

Writes
- `work_precision.csv`: one row per configuration × gait (the reference's rows too, varied =
  "reference"): config, label, varied (the settings that differ from the default), integrator,
  dt_s, precision, newton_tol, discretisation, n_arc, n_limb, gait, duration_s, steps,
  speed_mm_s, signed_speed_mm_s, reference_speed_mm_s, rel_error, max_rel_error, run_time_s,
  robot_steps_per_s, robot_seconds_per_wall_s (simulated robot-seconds per wall second), newton_iterations_mean, status, pareto (on the front of max
  error against run time), reference, arch, machine, commit, timestamp;
- `work_precision_orders.csv`: observed convergence order in h of each integrator at each
  discretisation, per gait and for the max over gaits: slope of log error against log h over all
  h (order_fit), over the two smallest h (order_fine) and the two largest (order_coarse);
- `work_precision.png`: error against run time (log-log, Pareto front marked, labels) and error
  against h per integrator and discretisation.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd

import taichi_star
from taichi_star import SolverConfig, StarParams

from . import cli, provenance

DESCRIPTION = ("Run time against error: h, precision, Newton tolerance, discretisation and "
               "integrator, five gaits' 3-cycle speeds against a refined reference.")

H_MS = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0)
QUICK_H_MS = (1.0, 2.0)
DISCRETISATIONS = {"0.5x": (9, 3), "1x": (18, 6), "2x": (36, 12)}
"""Name -> (n_arc, n_limb): ½×, 1× (the paper's N = 193) and 2×."""
F32_TOLERANCES = (1e-7, 1e-6)
"""f32 cannot converge below ~1e-7 m (SolverConfig refuses it)."""
QUICK_DURATION_S = 0.1
QUICK_GAITS = ("A1+A2", "A1+A3")

INTEGRATORS = ("euler", "bdf2")
"""The integrator axis."""

ORDER_COLUMNS = ["integrator", "discretisation", "n_arc", "n_limb", "gait", "n_points",
                 "h_min_ms", "h_max_ms", "order_fit", "order_fine", "order_coarse"]


@dataclass(frozen=True)
class Config:
    """One solver/discretisation setting. dt_s in s, newton_tol in m."""

    dt_s: float = 1e-3
    precision: str = "f64"
    newton_tol: float = 1e-10
    discretisation: str = "1x"
    integrator: str = "euler"

    def solver(self) -> SolverConfig:
        return SolverConfig(dt=self.dt_s, precision=self.precision, newton_tol=self.newton_tol,
                            integrator=self.integrator)

    def params(self, gaits):
        n_arc, n_limb = DISCRETISATIONS[self.discretisation]
        return [StarParams(gait=g, n_arc=n_arc, n_limb=n_limb) for g in gaits]

    def varied(self) -> str:
        """The fields that differ from the default setting ("default" when none)."""
        names = [name for name in self.__dataclass_fields__
                 if getattr(self, name) != getattr(DEFAULT, name)]
        return ",".join(names) or "default"

    def label(self) -> str:
        """Short label: the settings that differ from the default."""
        parts = []
        if self.dt_s != DEFAULT.dt_s:
            parts.append(f"h={self.dt_s * 1e3:g}ms")
        if self.integrator != DEFAULT.integrator:
            parts.append(self.integrator)
        if self.precision != DEFAULT.precision:
            parts.append(self.precision)
        if self.newton_tol != DEFAULT.newton_tol:
            parts.append(f"tol={self.newton_tol:.0e}")
        if self.discretisation != DEFAULT.discretisation:
            parts.append(self.discretisation)
        return " ".join(parts) or "default"


DEFAULT = Config()
REFERENCE = Config(dt_s=1.25e-4, newton_tol=1e-12, discretisation="2x", integrator=INTEGRATORS[-1])


def configurations(quick: bool):
    """The configurations to run (reference excluded), deduplicated, f64 first (a precision
    switch re-initialises Taichi)."""
    if quick:
        configs = [replace(DEFAULT, dt_s=h * 1e-3, integrator=integrator)
                   for integrator in INTEGRATORS for h in QUICK_H_MS]
        configs.append(replace(DEFAULT, newton_tol=1e-6))
    else:
        configs = [replace(DEFAULT, dt_s=h * 1e-3, integrator=integrator, discretisation=disc)
                   for disc in ("1x", "2x") for integrator in INTEGRATORS for h in H_MS]
        configs += [replace(DEFAULT, newton_tol=tol) for tol in (1e-6, 1e-8)]
        configs += [replace(DEFAULT, discretisation="0.5x")]
        configs += [replace(DEFAULT, precision="f32", newton_tol=tol) for tol in F32_TOLERANCES]
    unique = list(dict.fromkeys(configs))
    return sorted(unique, key=lambda c: c.precision != "f64")


def run_config(config: Config, gaits, cycles, duration_s, arch, progress=False):
    """(summary, run_time_s, steps) of one batch of the gaits: a one-step call compiles, then
    the timed call simulates `duration_s` (or `cycles` periods)."""
    params = config.params(gaits)
    solver = config.solver()
    duration = duration_s if duration_s is not None else cycles * params[0].period
    taichi_star.simulate(params, solver.dt, solver=solver, arch=arch)
    start = time.perf_counter()
    result = taichi_star.simulate(params, duration, solver=solver, arch=arch, progress=progress)
    run_time = time.perf_counter() - start
    return result.summary, run_time, int(round(duration / solver.dt))


def config_rows(config, summary, run_time, steps, reference_speeds):
    """The rows of one configuration: one per gait with its error against the reference."""
    n_arc, n_limb = DISCRETISATIONS[config.discretisation]
    ok = (summary["status"] == "ok").to_numpy()
    speed = summary["speed_mm_s"].to_numpy(dtype=float)
    reference = np.array([reference_speeds[g] for g in summary["gait"]])
    error = np.where(ok, np.abs(speed - reference) / np.abs(reference), np.nan)
    largest = float(np.max(error)) if np.isfinite(error).all() else math.nan
    duration = steps * config.dt_s
    return pd.DataFrame({
        "label": config.label(), "varied": config.varied(), "integrator": config.integrator,
        "dt_s": config.dt_s, "precision": config.precision, "newton_tol": config.newton_tol,
        "discretisation": config.discretisation, "n_arc": n_arc, "n_limb": n_limb,
        "gait": summary["gait"].to_numpy(), "duration_s": duration, "steps": steps,
        "speed_mm_s": speed, "signed_speed_mm_s": summary["signed_speed_mm_s"].to_numpy(),
        "reference_speed_mm_s": reference, "rel_error": error, "max_rel_error": largest,
        "run_time_s": run_time, "robot_steps_per_s": len(summary) * steps / run_time,
        "robot_seconds_per_wall_s": len(summary) * duration / run_time,
        "newton_iterations_mean": summary["newton_iterations_mean"].to_numpy(),
        "status": summary["status"].to_numpy()})


def pareto_front(run_time, error) -> np.ndarray:
    """Mask of the points no other point beats in both run time and error (NaN error: never on
    the front)."""
    run_time, error = np.asarray(run_time, float), np.asarray(error, float)
    mask = np.zeros(len(run_time), dtype=bool)
    best = math.inf
    for index in np.lexsort((error, run_time)):
        if np.isfinite(error[index]) and error[index] < best:
            mask[index] = True
            best = error[index]
    return mask


def _slope(h, error):
    return float(np.polyfit(np.log(h), np.log(error), 1)[0]) if len(h) >= 2 else math.nan


def convergence_orders(table: pd.DataFrame) -> pd.DataFrame:
    """Observed order in h per integrator and discretisation (f64, default tolerance), per gait
    and for the max over gaits: least-squares slope of log error on log h over all h with a
    positive finite error, and over the two smallest and the two largest such h."""
    axis = table[(table["varied"] != "reference") & (table["precision"] == DEFAULT.precision)
                 & (table["newton_tol"] == DEFAULT.newton_tol)]
    rows = []
    for (integrator, disc), part in axis.groupby(["integrator", "discretisation"], sort=False):
        per_config = part.groupby("dt_s")["max_rel_error"].first()
        series = {gait: rows_.set_index("dt_s")["rel_error"]
                  for gait, rows_ in part.groupby("gait", sort=False)}
        series["max"] = per_config
        for gait, errors in series.items():
            errors = errors[np.isfinite(errors) & (errors > 0)].sort_index()
            if len(errors) < 2:
                continue
            h = errors.index.to_numpy(dtype=float) * 1e3
            values = errors.to_numpy(dtype=float)
            n_arc, n_limb = DISCRETISATIONS[disc]
            rows.append({"integrator": integrator, "discretisation": disc, "n_arc": n_arc,
                         "n_limb": n_limb, "gait": gait, "n_points": len(h),
                         "h_min_ms": h[0], "h_max_ms": h[-1], "order_fit": _slope(h, values),
                         "order_fine": _slope(h[:2], values[:2]),
                         "order_coarse": _slope(h[-2:], values[-2:])})
    return pd.DataFrame(rows, columns=ORDER_COLUMNS)


def plot_work_precision(csv_path, orders_csv_path, png_path):
    """Error against run time (log-log, Pareto front, labels) and error against h."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    orders = pd.read_csv(orders_csv_path)
    configs = table[table["varied"] != "reference"].groupby("config", sort=False).first()
    fig, (left, right) = plt.subplots(1, 2, figsize=(15, 6))
    groups = configs.groupby(["integrator", "discretisation", "precision"], sort=False)
    for (integrator, disc, precision), part in groups:
        shown = part[np.isfinite(part["max_rel_error"])]
        left.plot(shown["run_time_s"], shown["max_rel_error"], "o", ms=5, alpha=0.8,
                  label=f"{integrator} {disc} {precision}")
        for _, row in shown.iterrows():
            left.annotate(row["label"], (row["run_time_s"], row["max_rel_error"]), fontsize=6,
                          xytext=(3, 3), textcoords="offset points")
    front = configs[configs["pareto"].astype(bool)].sort_values("run_time_s")
    left.step(front["run_time_s"], front["max_rel_error"], "r-", where="post", lw=1.2,
              label="Pareto front")
    left.plot(front["run_time_s"], front["max_rel_error"], "o", mfc="none", mec="r", ms=10)
    left.axhline(0.01, color="k", ls=":", lw=1, label="1 %")
    failed = configs[~np.isfinite(configs["max_rel_error"])]
    title = "max relative speed error over gaits vs run time"
    if len(failed):
        title += f" ({len(failed)} configuration(s) with a failed instance not shown)"
    left.set_title(title, fontsize=9)
    left.set_xlabel("run time of the batch (s)")
    left.set_ylabel("max relative error of the speed")

    axis = configs[(configs["precision"] == DEFAULT.precision)
                   & (configs["newton_tol"] == DEFAULT.newton_tol)]
    for (integrator, disc), part in axis.groupby(["integrator", "discretisation"], sort=False):
        part = part[np.isfinite(part["max_rel_error"])].sort_values("dt_s")
        if len(part) < 2:
            continue
        order = orders[(orders["integrator"] == integrator) & (orders["discretisation"] == disc)
                       & (orders["gait"] == "max")]["order_fit"]
        slope = f", order {order.iloc[0]:.2f}" if len(order) else ""
        right.plot(part["dt_s"] * 1e3, part["max_rel_error"], "o-",
                   label=f"{integrator} {disc}{slope}")
    right.set_xlabel("time step h (ms)")
    right.set_ylabel("max relative error of the speed")
    reference = table[table["varied"] == "reference"].iloc[0]
    right.set_title(f"error vs h (reference: h = {reference['dt_s'] * 1e3:g} ms, "
                    f"{reference['integrator']}, {reference['discretisation']}, tol "
                    f"{reference['newton_tol']:.0e})", fontsize=9)
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    fig.suptitle(f"{table['gait'].nunique()} gaits, {table['duration_s'].max():.4g} s from rest, "
                 f"{table['machine'].iloc[0]}, {table['commit'].iloc[0]}", fontsize=9)
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
    return png_path


def build_parser():
    parser = cli.StudyParser("work_precision", DESCRIPTION)
    parser.add_argument("--gaits", default="paper", quick=",".join(QUICK_GAITS),
                        help="paper (the five Fig. 4 gaits) or a list A1,A1+A2")
    parser.add_argument("--cycles", type=float, default=3.0,
                        help=f"cycles from rest (default 3; --quick simulates "
                             f"{QUICK_DURATION_S} s)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    gaits = cli.resolve_gaits(args.gaits)
    duration = QUICK_DURATION_S if args.quick else None
    configs = configurations(args.quick)
    out = cli.Output(args, argv or [], model={"gaits": gaits, "discretisations": DISCRETISATIONS},
                     solver={"reference": REFERENCE, "configurations": configs})
    provenance_columns = {"arch": args.arch,
                          "machine": provenance.machine_columns(args.arch)["machine"],
                          "commit": provenance.short_commit(), "timestamp": out.provenance["date"],
                          "reference": REFERENCE.label()}

    def steps_of(config):
        length = duration if duration is not None else args.cycles * StarParams().period
        return int(round(length / config.dt_s)) * len(gaits)

    bar = None
    if not args.no_progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=sum(steps_of(c) for c in [REFERENCE, *configs]), unit="robot-step",
                   desc="work-precision", unit_scale=True)
    # the reference is the longest run: its own bar shows it moving
    summary, run_time, steps = run_config(REFERENCE, gaits, args.cycles, duration, args.arch,
                                          progress=bar is not None)
    if (summary["status"] != "ok").any():
        raise RuntimeError(f"the reference run failed:\n{summary[['gait', 'status']]}")
    reference_speeds = dict(zip(summary["gait"], summary["speed_mm_s"]))
    parts = [config_rows(REFERENCE, summary, run_time, steps, reference_speeds)
             .assign(varied="reference", label="reference")]
    if bar is not None:
        bar.update(steps_of(REFERENCE))
    for config in configs:
        if bar is not None:
            bar.set_postfix_str(config.label())
        summary, run_time, steps = run_config(config, gaits, args.cycles, duration, args.arch)
        parts.append(config_rows(config, summary, run_time, steps, reference_speeds))
        if bar is not None:
            bar.update(steps_of(config))
    if bar is not None:
        bar.close()

    table = pd.concat(parts, ignore_index=True)
    table.insert(0, "config", np.repeat(np.arange(len(parts)), len(gaits)))
    per_config = table.groupby("config", sort=False)[["run_time_s", "max_rel_error"]].first()
    candidates = per_config.index != 0  # the reference (config 0) is not a candidate
    front = np.zeros(len(per_config), dtype=bool)
    front[candidates] = pareto_front(per_config["run_time_s"][candidates],
                                     per_config["max_rel_error"][candidates])
    table["pareto"] = front[table["config"].to_numpy()]
    for name, value in provenance_columns.items():
        table[name] = value

    csv_path = out.write_csv(table, "work_precision.csv")
    orders = convergence_orders(table)
    orders_path = out.write_csv(orders, "work_precision_orders.csv")
    out.wrote(plot_work_precision(csv_path, orders_path, out.path("work_precision.png")))
    report(table, orders)
    out.report()
    return table


def report(table: pd.DataFrame, orders: pd.DataFrame):
    """Print the configurations by run time and the observed orders (max over gaits)."""
    configs = table[table["varied"] != "reference"].groupby("config", sort=False).first()
    print(f"\nreference: {table['reference'].iloc[0]}")
    print(f"{'configuration':<28} {'run time s':>10} {'max rel err':>12}  pareto")
    for _, row in configs.sort_values("run_time_s").iterrows():
        print(f"{row['label']:<28} {row['run_time_s']:10.3f} {row['max_rel_error']:12.3e}  "
              f"{'*' if row['pareto'] else ''}")
    print("\nobserved order in h (slope of log max error vs log h; at 1x the discretisation "
          "error against the 2x reference dominates):")
    for _, row in orders[orders["gait"] == "max"].iterrows():
        print(f"  {row['integrator']:<6} {row['discretisation']:<5} fit {row['order_fit']:.2f} "
              f"(fine {row['order_fine']:.2f}, coarse {row['order_coarse']:.2f}) over "
              f"h = {row['h_min_ms']:g}..{row['h_max_ms']:g} ms")
