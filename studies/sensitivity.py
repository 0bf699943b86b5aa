"""Global sensitivity: Sobol indices of each gait's signed speed to the model's parameters.

    python -m studies sensitivity [--vary NAME=LOW:HIGH[:log] ...] [--set NAME=VALUE ...]
                                  [--gaits paper|A1,...] [--base-samples 128] [--cycles 3]
                                  [--seed 1] [--run-dir DIR] [--resume]
                                  [--arch cpu|gpu] [--out results/] [--quick]
                                  [--workers N | --scheduler tcp://HOST:PORT]

Saltelli sampling (`SALib.sample.sobol`, first-order and total indices only) of N base samples
in the unit cube of the `--vary` box gives N (D + 2) parameter points; each point is simulated
on every gait (N (D + 2) × gaits instances, in resumable chunks of one `simulate` call each, with
a progress bar), and `SALib.analyze.sobol` turns each gait's signed speed (over `--cycles` cycles
from rest, the Fig. 4c metric) into S1 (first-order: the share of the variance explained by the
parameter alone) and ST (total: including all its interactions), with bootstrap 95 % confidence
half-widths. Log axes are sampled uniformly in the logarithm, so the indices are those of a
log-uniform parameter. The default box (`DEFAULT_BOX`) spans each fluid and material
coefficient a factor of about 2-3 either side of the paper's value, damping from none to 2 ms and
the measured radii by a few millimetres and the thickness and masses by 10-30 %.

Writes `sensitivity_samples.csv` (every point: unit coordinates and values),
`sensitivity_runs.csv` (every instance: point, gait, signed speed, status), `sensitivity.csv`
(gait, parameter, its range, S1, S1_conf, ST, ST_conf, n_failed) and `sensitivity.png` (bars
drawn from `sensitivity.csv`). A failed instance makes its gait's indices NaN (Saltelli's
estimators need every point); the count is in n_failed.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from taichi_star.params import SolverConfig

from . import common, distributed, identify, runs

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
DEFAULT_DT = 3.15e-3
"""Time step, s: 1000 steps per 3.15-s cycle. Implicit Euler's speeds sit on a plateau from
h = 8 ms down to 0.25 ms (the work-precision study), so this costs a third of the paper's 1 ms
for the same speeds (measured for the paper gaits: see the README)."""
CONF_LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 200


def saltelli_units(dimension: int, base_samples: int, seed: int) -> np.ndarray:
    """Saltelli's sample of the unit cube for first-order and total indices:
    (base_samples × (dimension + 2), dimension), scrambled Sobol' sequence seeded by `seed`."""
    from SALib.sample import sobol as sobol_sample
    problem = {"num_vars": dimension, "names": [f"u{d}" for d in range(dimension)],
               "bounds": [[0.0, 1.0]] * dimension}
    return sobol_sample.sample(problem, base_samples, calc_second_order=False, seed=seed)


def sobol_indices(names: Sequence[str], outputs: Mapping[str, np.ndarray],
                  seed: int = 1) -> pd.DataFrame:
    """S1, S1_conf, ST, ST_conf (95 % bootstrap half-widths) of each output to each input, from
    outputs evaluated on `saltelli_units(len(names), N, ...)` in its row order: outputs maps an
    output name (e.g. a gait) to an array (N (D + 2),). Returns one row per output × input
    (columns output, parameter, S1, S1_conf, ST, ST_conf, n_failed); an output with a non-finite
    value gets NaN indices and its count of such values in n_failed."""
    from SALib.analyze import sobol
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
    plt = common.use_agg()
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
        ax.set_ylabel(gait.replace("+", "&"))
        ax.set_ylim(-0.1, 1.1)  # the indices' range; wider confidence bars run off it
        ax.set_xticks(x, part["parameter"], rotation=35, ha="right", fontsize=8)
    axes[0, 0].legend(fontsize=7, ncol=2)
    samples = int(table["n_base_samples"].iloc[0])
    axes[0, 0].set_title(f"Sobol indices of the signed speed (N = {samples} base samples, "
                         f"bars: 95 % confidence)", fontsize=9)
    fig.tight_layout()
    fig.savefig(png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def solver_for(args) -> SolverConfig:
    """The study's solver: implicit Euler with the chord Jacobian (the same converged steps to
    newton_tol as Newton, faster) at `--dt`, default DEFAULT_DT (QUICK_DT with --quick)."""
    dt = args.dt if args.dt is not None else (common.QUICK_DT if args.quick else DEFAULT_DT)
    try:
        return SolverConfig(dt=dt, jacobian="chord")
    except ValueError as error:
        raise common.StudyArgumentError(f"--dt: {error}") from None


def build_parser():
    parser = common.common_parser("sensitivity", DESCRIPTION)
    parser._option_string_actions["--dt"].help = f"time step, s (default {DEFAULT_DT})"
    parser.add_argument("--vary", action="append", default=None, metavar="NAME=LOW:HIGH[:log]",
                        help="a real-valued StarParams field and its range, repeatable "
                             "(default: the 14 of DEFAULT_BOX: " + " ".join(DEFAULT_BOX) + ")")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="fix another StarParams field, e.g. --set jet_mode=always")
    parser.add_argument("--gaits", default="paper",
                        help="gaits: paper (the five, default) or a comma list")
    parser.add_argument("--base-samples", type=int, default=None,
                        help=f"Saltelli base samples N, a power of 2 (default "
                             f"{DEFAULT_BASE_SAMPLES}; {QUICK_BASE_SAMPLES} with --quick); "
                             f"instances = N (D + 2) × gaits")
    parser.add_argument("--cycles", type=float, default=3.0,
                        help="cycles from rest per instance (default 3, as Fig. 4c)")
    parser.add_argument("--seed", type=int, default=1, help="sampling and bootstrap seed")
    parser.add_argument("--run-dir", default=None, metavar="DIR",
                        help="run folder for the finished chunks (default <out>/sensitivity_run)")
    parser.add_argument("--resume", action="store_true",
                        help="continue the run in the run folder, skipping finished chunks")
    distributed.add_arguments(parser)
    return parser


def main(argv=None):
    args = build_parser().parse_args(argv)
    common.check_positive(args.cycles, "--cycles")
    samples = args.base_samples if args.base_samples is not None else (
        QUICK_BASE_SAMPLES if args.quick else DEFAULT_BASE_SAMPLES)
    if samples < 2 or samples & (samples - 1):
        raise common.StudyArgumentError(f"--base-samples must be a power of 2 >= 2 (Sobol' "
                                        f"sequence balance), got {samples}")
    if args.seed < 0:
        raise common.StudyArgumentError(f"--seed must be >= 0, got {args.seed}")
    gaits = common.resolve_gaits(args.gaits)
    box = [identify.parse_range_spec(text, "--vary") for text in (args.vary or DEFAULT_BOX)]
    overrides = common.parse_overrides(args.set)
    clash = set(overrides) & ({spec.name for spec in box} | {"gait"})
    if clash:
        raise common.StudyArgumentError(f"--set {sorted(clash)[0]}: varied or fixed by the study")
    try:
        base = common.base_params(args).replace(**overrides)
    except (ValueError, TypeError) as error:
        raise common.StudyArgumentError(f"--set: {error}") from None
    identify.check_box(box, base, "--vary")
    solver = solver_for(args)
    distributed.validate(args)
    run_dir = Path(args.run_dir) if args.run_dir is not None else Path(args.out) / "sensitivity_run"
    previous = runs.previous_chunk_size(run_dir) if args.resume else None
    if args.chunk_size is None and previous is not None:
        args.chunk_size = previous  # resume with the run's own chunks
    if args.chunk_size is not None and args.chunk_size < 1:
        raise common.StudyArgumentError(f"--chunk-size must be >= 1, got {args.chunk_size}")

    units = saltelli_units(len(box), samples, args.seed)
    values = identify.box_values(box, units)
    params = identify.box_params(box, values, base, gaits)
    out = common.out_dir(args)
    names = [spec.name for spec in box]
    sample_table = pd.DataFrame({f"u_{n}": units[:, d] for d, n in enumerate(names)})
    for d, name in enumerate(names):
        sample_table[name] = values[:, d]
    sample_table.insert(0, "point", np.arange(len(units)))
    paths = [common.write_csv(sample_table, out / "sensitivity_samples.csv")]
    description = {"box": [spec.spec for spec in box], "fixed": {k: str(v) for k, v in
                                                                  overrides.items()},
                   "gaits": gaits, "base_samples": samples, "seed": args.seed,
                   "cycles": args.cycles, "quick": args.quick}
    with distributed.executor_for(args) as executor:
        chunk = distributed.default_chunk_size(args, len(params), executor.n_workers,
                                               cpu_default=CHUNK)
        summary = common.run_batch(
            params, cycles=args.cycles,
            duration_s=common.QUICK_DURATION_S if args.quick else None, solver=solver,
            arch=args.arch, chunk_size=chunk, progress=not args.no_progress, executor=executor,
            run_dir=run_dir, resume=args.resume, description=description).summary
    ok = (summary["status"] == "ok").to_numpy()
    run_table = pd.DataFrame({
        "point": np.repeat(np.arange(len(units)), len(gaits)),
        "gait": summary["gait"], "status": summary["status"],
        "signed_speed_mm_s": np.where(ok, summary["signed_speed_mm_s"], np.nan),
        "speed_mm_s": np.where(ok, summary["speed_mm_s"], np.nan)})
    paths.append(common.write_csv(run_table, out / "sensitivity_runs.csv"))

    outputs = {gait: run_table.loc[run_table["gait"] == gait, "signed_speed_mm_s"].to_numpy()
               for gait in gaits}
    indices = sobol_indices(names, outputs, seed=args.seed).rename(columns={"output": "gait"})
    ranges = {spec.name: spec for spec in box}
    indices.insert(2, "low", [ranges[n].low for n in indices["parameter"]])
    indices.insert(3, "high", [ranges[n].high for n in indices["parameter"]])
    indices.insert(4, "log", [ranges[n].log for n in indices["parameter"]])
    indices["n_base_samples"] = samples
    indices["n_instances"] = len(params)
    indices["cycles"] = args.cycles
    indices["quick"] = args.quick  # --quick: QUICK_DURATION_S from rest instead of the cycles
    csv = common.write_csv(indices, out / "sensitivity.csv")
    paths += [csv, plot_sensitivity(csv, out / "sensitivity.png")]
    print(common.describe(paths))
    failed = int((~ok).sum())
    print(f"{len(params)} instances ({len(units)} points × {len(gaits)} gaits), {failed} not ok")
    with pd.option_context("display.width", 160, "display.max_rows", 200):
        print(indices[["gait", "parameter", "S1", "S1_conf", "ST", "ST_conf"]]
              .round(3).to_string(index=False))
    return indices
