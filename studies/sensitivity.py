"""Global sensitivity: Sobol indices of each gait's signed speed to the model's parameters.

    python -m studies sensitivity [--vary NAME=LOW:HIGH[:log] ...]
                                  [--preset paper|accurate|identified]
                                  [--set NAME=VALUE ...] [--gaits paper|A1,...]
                                  [--base-samples 128] [--cycles 3] [--dt 3.15e-3] [--seed 1]
                                  [--out DIR] [--run-dir DIR] [--resume] [--quick]
                                  [--arch cpu|gpu] [--workers N | --scheduler tcp://HOST:PORT]

Saltelli sampling (`SALib.sample.sobol`, first-order and total indices only) of N base samples
in the unit cube of the `--vary` box gives N (D + 2) parameter points; each point is simulated
on every gait (N (D + 2) × gaits instances, one `taichi_star.batch.run_batch` in resumable
chunks with a progress bar), and `SALib.analyze.sobol` turns each gait's signed speed (over
`--cycles` cycles from rest, the Fig. 4c metric) into S1 (first-order: the share of the
variance explained by the parameter alone) and ST (total: including all its interactions), with
bootstrap 95 % confidence half-widths. Log axes are sampled uniformly in the logarithm, so the
indices are those of a log-uniform parameter. The default box (`DEFAULT_BOX`) spans each fluid
and material coefficient a factor of about 2-3 either side of the paper's value, damping from
none to 2 ms and the measured radii by a few millimetres and the thickness and masses by
10-30 %.

Writes into `--out` (default a fresh `runs/sensitivity/<timestamp>/`), each table with its
provenance sidecar: `sensitivity_samples.csv` (every point: unit coordinates u_<name> and the
values, in columns named with their unit), `sensitivity_runs.csv` (every instance: point, gait,
signed speed, status), `sensitivity.csv` (gait, parameter, its range low–high in `unit`, S1,
S1_conf, ST, ST_conf, n_failed) and `sensitivity.png` (bars drawn from `sensitivity.csv`). A
failed instance makes its gait's indices NaN (Saltelli's estimators need every point); the count
is in n_failed.

Resumable: every finished chunk is stored, verified, in the run store (`--run-dir`, default
`<out>/chunks/`); after a kill, the same command with `--out` of that run and `--resume` skips
the finished chunks (a store holding another sample is refused).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from taichi_star import SOLVER_RANGES, SolverConfig
from taichi_star.batch import run_batch
from taichi_star.extras import require
from taichi_star.output import column_unit

from . import cli, identify

DESCRIPTION = ("Sobol indices (SALib, Saltelli sampling) of each paper gait's signed speed to "
               "the fluid, material, damping and geometry parameters.")

DEFAULT_BOX = [
    "alpha=0.4:1.2",                    # jet ratio, paper 0.8: ±50 %
    "added_mass_coeff=0.5:1.5",         # rod added mass, paper 1: ±50 %
    "drag_perpendicular=0.5:2:log",     # normal rod drag, paper 1: ×/÷ 2
    "drag_parallel=0.003:0.03:log",     # axial rod drag, paper 0.01: ×/÷ ~3
    "cylinder_drag=3:30:log",           # hub drag, paper 10: ×/÷ ~3
    "youngs_modulus=2.5e6:1e7:log",     # arc modulus E, paper 5 MPa: ×/÷ 2
    "limb_stiffness_ratio=30:300:log",  # E_limb / E, paper 100: ×/÷ ~3
    "damping_time=0:0.002",             # Kelvin-Voigt τ, paper 0 (none) to 2 ms
    "joint_radius=0.021:0.025",         # paper 24 mm; 25.6 mm is the geometric limit
    "tip_radius=0.048:0.056",           # paper 52 mm: ±4 mm
    "cylinder_added_mass_coeff=0:1",    # paper 0; 1 = potential flow around a cylinder
    "thickness=0.0031:0.0037",          # rod thickness, paper 3.4 mm: ±10 %
    "foam_density=500:900",             # limbs, paper 700 kg/m³: ±30 % (absorbed water)
    "cylinder_mass_per_height=0.8:1.2",  # hub + payload, paper 0.98 kg/m: ±20 %
]
"""The default box: 14 parameters (ranges chosen as stated in each comment)."""
DEFAULT_BASE_SAMPLES = 128
"""With the 14 default parameters: 128 × 16 points × 5 gaits = 10,240 instances."""
QUICK_BASE_SAMPLES = 4
CHUNK = 256
"""Instances per chunk on the CPU: a kill loses little of a run of thousands."""
DEFAULT_DT = 3.15e-3
"""Time step, s: 1000 steps per 3.15-s cycle. Implicit Euler's speeds sit on a plateau from
h = 8 ms down to 0.25 ms (the work-precision study), so this costs a third of the paper's 1 ms
for the same speeds (measured for the paper gaits: see the README)."""
CONF_LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 200


def check_seed(seed):
    """ValueError naming seed unless it is an integer >= 1: SALib seeds its sampling and its
    bootstrap only for a seed that is true, so 0 gave other confidence intervals at every run
    (an audit, 2026-12)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 1:
        raise ValueError(f"seed must be an integer >= 1 (SALib takes 0 for no seed), got "
                         f"{seed!r}")


def saltelli_units(dimension: int, base_samples: int, seed: int) -> np.ndarray:
    """Saltelli's sample of the unit cube for first-order and total indices:
    (base_samples × (dimension + 2), dimension), scrambled Sobol' sequence seeded by `seed`
    (an integer >= 1: `check_seed`)."""
    check_seed(seed)
    sobol_sample = require("SALib.sample.sobol", "studies")
    problem = {"num_vars": dimension, "names": [f"u{d}" for d in range(dimension)],
               "bounds": [[0.0, 1.0]] * dimension}
    return sobol_sample.sample(problem, base_samples, calc_second_order=False, seed=seed)


def sobol_indices(names: Sequence[str], outputs: Mapping[str, np.ndarray],
                  seed: int = 1) -> pd.DataFrame:
    """S1, S1_conf, ST, ST_conf (95 % bootstrap half-widths) of each output to each input, from
    outputs evaluated on `saltelli_units(len(names), N, ...)` in its row order: outputs maps an
    output name (e.g. a gait) to an array (N (D + 2),). Returns one row per output × input
    (columns output, parameter, S1, S1_conf, ST, ST_conf, n_failed); an output with a non-finite
    value gets NaN indices and its count of such values in n_failed. `seed`: the bootstrap's,
    an integer >= 1 (`check_seed`)."""
    check_seed(seed)
    sobol = require("SALib.analyze.sobol", "studies")
    problem = {"num_vars": len(names), "names": list(names),
               "bounds": [[0.0, 1.0]] * len(names)}
    rows = []
    for output, values in outputs.items():
        values = np.asarray(values, dtype=np.float64)
        failed = int((~np.isfinite(values)).sum())
        if failed:
            indices = {key: np.full(len(names), np.nan) for key in
                       ("S1", "S1_conf", "ST", "ST_conf")}
        else:
            indices = sobol.analyze(problem, values, calc_second_order=False,
                                    num_resamples=BOOTSTRAP_RESAMPLES, conf_level=CONF_LEVEL,
                                    seed=seed)
        for d, name in enumerate(names):
            rows.append({"output": output, "parameter": name,
                         **{key: float(indices[key][d]) for key in
                            ("S1", "S1_conf", "ST", "ST_conf")},
                         "n_failed": failed})
    return pd.DataFrame(rows)


def plot_sensitivity(csv_path, png_path) -> Path:
    """One panel per gait from a sensitivity CSV: S1 and ST bars per parameter with their 95 %
    confidence half-widths."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    gaits = list(dict.fromkeys(table["gait"]))
    fig, axes = plt.subplots(len(gaits), 1, figsize=(8.5, 2.2 * len(gaits) + 0.8), sharex=True,
                             squeeze=False)
    for ax, gait in zip(axes[:, 0], gaits):
        part = table[table["gait"] == gait]
        x = np.arange(len(part))
        ax.bar(x - 0.2, part["S1"], 0.4, yerr=part["S1_conf"], capsize=2, label="S1 (first order)")
        ax.bar(x + 0.2, part["ST"], 0.4, yerr=part["ST_conf"], capsize=2, label="ST (total)")
        ax.axhline(0, color="k", lw=0.5)
        ax.set_ylabel(gait)
        ax.set_ylim(-0.1, 1.1)  # the indices' range; wider confidence bars run off it
        ax.set_xticks(x, part["parameter"], rotation=35, ha="right", fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=2)
    samples = int(table["n_base_samples"].iloc[0])
    settings = cli.run_settings(csv_path)
    axes[0, 0].set_title(f"Sobol indices of the signed speed (N = {samples} base samples, "
                         f"bars: 95 % confidence)" + (f"\n{settings}" if settings else ""),
                         fontsize=9)
    return cli.save_figure(fig, png_path)


def solver(args, box: Sequence[identify.ParameterRange] = ()) -> SolverConfig:
    """The study's solver: the --preset's with the chord Jacobian (the same converged steps to
    newton_tol as Newton, faster) at --dt (default DEFAULT_DT, QUICK_DT under --quick); the
    run's length checked at the periods of the `box` (`cli.solver`)."""
    return cli.solver(args, periods=cli.range_periods(box)).replace(jacobian="chord")


def build_parser():
    parser = cli.StudyParser("sensitivity", DESCRIPTION)
    parser.add_argument("--vary", action="append", default=None, metavar="NAME=LOW:HIGH[:log]",
                        help="a real-valued StarParams field and its range, repeatable "
                             "(default: the 14 of DEFAULT_BOX: " + " ".join(DEFAULT_BOX) + ")")
    parser.add_argument("--gaits", default="paper",
                        help=cli.GAITS_HELP)
    parser.add_argument("--base-samples", type=int, default=DEFAULT_BASE_SAMPLES,
                        quick=QUICK_BASE_SAMPLES,
                        help=f"Saltelli base samples N, a power of 2; instances = N (D + 2) × "
                             f"gaits, at most {cli.MAX_INSTANCES:,}")
    parser.add_argument("--seed", type=int, default=1, help="sampling and bootstrap seed")
    cli.add_model_flags(parser, fixed=("gait",))
    parser.add_argument("--dt", type=float, default=DEFAULT_DT, quick=cli.QUICK_DT,
                        help=f"time step, s, in (0, {SOLVER_RANGES['dt'][1]:g}], with either "
                             f"preset")
    cli.add_cycles_flag(parser)
    cli.add_resume_flags(parser)
    cli.add_execution_flags(parser, chunk_size=CHUNK)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    samples = args.base_samples
    if samples < 2 or samples & (samples - 1):
        raise cli.StudyArgumentError(f"--base-samples must be a power of 2 >= 2 (Sobol' "
                                     f"sequence balance), got {samples}")
    if args.seed < 1:
        # SALib seeds nothing for 0: another sample and other intervals at every run
        raise cli.StudyArgumentError(f"--seed must be >= 1, got {args.seed}")
    gaits = cli.resolve_gaits(args.gaits, firing=True)
    box = [identify.parse_range_spec(text, "--vary") for text in (args.vary or DEFAULT_BOX)]
    instances = samples * (len(box) + 2) * len(gaits)
    if instances > cli.MAX_INSTANCES:
        raise cli.StudyArgumentError(
            f"--base-samples {samples}: {instances:,} instances ({samples} × ({len(box)} + 2) "
            f"points × {len(gaits)} gaits), more than the {cli.MAX_INSTANCES:,} a study runs")
    base = identify.model_with_box(args, box, "--vary")
    solver_config = solver(args, box)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver_config,
                     extra={"box": [spec.spec for spec in box], "gaits": gaits,
                            "base_samples": samples, "seed": args.seed})
    run_dir = cli.run_store(args, out)

    units = saltelli_units(len(box), samples, args.seed)
    values = identify.box_values(box, units)
    # the batch's hours before its instances are built (as sweep: a million took minutes)
    periods = [values[:, d] for d, spec in enumerate(box) if spec.name == "period"]
    cli.tell_batch_work(args, solver_config, len(units) * len(gaits),
                        periods=periods[0] if periods else (), nodes=base.n_nodes)
    params = identify.box_params(box, values, base, gaits)
    # each axis by its own label and columns: two elements of one field (actuator_gains[1],
    # actuator_gains[2]) shared the field's name, and one's range and column overwrote the
    # other's (an audit, 2026-12)
    names = [spec.label for spec in box]
    sample_table = pd.DataFrame({f"u_{spec.key}": units[:, d] for d, spec in enumerate(box)})
    for d, spec in enumerate(box):
        sample_table[spec.column] = values[:, d]
    sample_table.insert(0, "point", np.arange(len(units)))
    # connected first: an unreachable scheduler leaves the folder empty, and it is removed
    with cli.executor(args, out) as executor, cli.batch_work_told():
        summary = run_batch(params, **cli.run_length(args), solver=solver_config,
                            arch=args.arch,
                            chunk_size=cli.chunk_size(args, len(params), executor.n_workers),
                            executor=executor, run_dir=run_dir, run_dir_flag="--run-dir",
                            resume=args.resume,
                            progress=not args.no_progress).summary
    # after the run: a resume that the run store refuses (other arguments) leaves the folder's
    # tables those of its own run (the samples were replaced before the refusal; an audit)
    out.write_csv(sample_table, "sensitivity_samples.csv")
    ok = (summary["status"] == "ok").to_numpy()
    run_table = pd.DataFrame({
        "point": np.repeat(np.arange(len(units)), len(gaits)),
        "gait": summary["gait"], "status": summary["status"],
        "signed_speed_mm_s": np.where(ok, summary["signed_speed_mm_s"], np.nan),
        "speed_mm_s": np.where(ok, summary["speed_mm_s"], np.nan)})
    out.write_csv(run_table, "sensitivity_runs.csv")

    outputs = {gait: run_table.loc[run_table["gait"] == gait, "signed_speed_mm_s"].to_numpy()
               for gait in gaits}
    indices = sobol_indices(names, outputs, seed=args.seed).rename(columns={"output": "gait"})
    ranges = {spec.label: spec for spec in box}
    indices.insert(2, "low", [ranges[n].low for n in indices["parameter"]])
    indices.insert(3, "high", [ranges[n].high for n in indices["parameter"]])
    indices.insert(4, "log", [ranges[n].log for n in indices["parameter"]])
    indices.insert(5, "unit", [column_unit(ranges[n].column) or "1" for n in indices["parameter"]])
    indices["n_base_samples"] = samples
    indices["n_instances"] = len(params)
    # --quick: QUICK_DURATION_S from rest instead of the cycles (it recorded 3: an audit,
    # 2026-12, as calibrate's)
    indices["cycles"] = math.nan if args.quick else args.cycles
    indices["quick"] = args.quick
    csv = out.write_csv(indices, "sensitivity.csv")
    out.wrote(plot_sensitivity(csv, out.path("sensitivity.png")))
    out.report()
    failed = int((~ok).sum())
    print(f"{len(params)} instances ({len(units)} points × {len(gaits)} gaits), {failed} not ok")
    with pd.option_context("display.width", 160, "display.max_rows", 200):
        print(indices[["gait", "parameter", "S1", "S1_conf", "ST", "ST_conf"]]
              .round(3).to_string(index=False))
    return indices
