"""Local sensitivities: the elasticity of each gait's signed speed to every parameter, beside
the Sobol indices.

    python -m studies elasticities [--preset paper|accurate|identified] [--set NAME=VALUE ...]
                                   [--gaits paper|A1,...] [--parameters NAME,...] [--cycles 3]
                                   [--dt S] [--sobol CSV] [--check NAME,...]
                                   [--prefix elasticities] [--out DIR] [--quick] [--arch cpu|gpu]

One `simulate` call with `sensitivities=` gives, for every gait at the model's parameters, the
exact derivative dv/dp of its signed speed v (over `--cycles` cycles from rest, the Fig. 4c
metric) with respect to every parameter p (`taichi_star.sensitivities`: the implicit function
theorem at each converged step). The default parameters are every differentiable StarParams
field (`DIFFERENTIABLE_FIELDS`) and each actuator's gain and delay, less the component heights
where they are 0 (the 2.5-D model off: no derivative there). The elasticity
d ln|v| / d ln p = (p / v)·dv/dp is the relative change of the speed per relative change of the
parameter; for a parameter at 0 (linear drag, jet inflow, the delays, damping in the paper's
model) it is 0 by definition, and only the absolute derivative says how the speed leaves 0.

Writes into `--out` (default a fresh `runs/elasticities/<timestamp>/`), each table with its
provenance sidecar: `<prefix>.csv`, one row per gait × parameter (gait, parameter, field,
actuator, fired, value, unit, signed_speed_mm_s, derivative, derivative_unit, elasticity,
at_zero, then S1, S1_conf, ST, ST_conf of the parameter for that gait from the Sobol table
`--sobol` where the parameter was in its box, NaN otherwise, and sobol_preset, the preset that
table was computed with), and `<prefix>.png`, drawn from it: a heatmap of the elasticities, gaits
× parameters, above the Sobol ST of the same cells. `--check NAME,...` also compares the
derivatives of those parameters with whole-run central differences at each parameter's own
step (`<prefix>_check.csv`; the measured agreement over 3 cycles is in docs/results.md).
"""

from __future__ import annotations

import hashlib
import time
import warnings
from pathlib import Path
from typing import Dict, List, Sequence

import numpy as np
import pandas as pd

from taichi_star import COMPONENT_HEIGHTS, Gait, SolverConfig, StarParams, simulate
from taichi_star.output import column_unit, read_provenance
from taichi_star.sensitivity_check import extrapolated_difference, whole_run_differences
from taichi_star.sensitivities import REPLICAS_PER_DIRECTION, parse_directions

from . import cli, identify, provenance

DESCRIPTION = ("Elasticities d ln|v| / d ln p of each paper gait's signed speed to every "
               "parameter (exact sensitivities), beside the Sobol indices.")

OUTPUT = "signed_speed_mm_s"
"""The output differentiated: the signed speed over the run (the Fig. 4c metric)."""
SOBOL_TABLE = cli.COMMITTED_RESULTS / "sensitivity.csv"
"""The committed Sobol indices (`python -m studies sensitivity`)."""
SOBOL_COLUMNS = ("S1", "S1_conf", "ST", "ST_conf")
CHECK_NEWTON_TOL = 1e-12
"""Newton tolerance of the check's runs, m (the sensitivities' own run keeps the preset's)."""


def default_parameters(base: StarParams) -> List[str]:
    """Every differentiable field, per-actuator ones as their eight numbers, less the component
    heights where they are 0 (`simulate` refuses a derivative across the 2.5-D switch; the
    heights are all 0 or all set)."""
    return cli.sensitivity_parameters("all", "--parameters", heights=cli.heights_in_all(base))


def direction(label: str):
    """The `taichi_star.sensitivities.Direction` of one parameter label ("alpha",
    "actuator_gains[2]"): its field, actuator index, value and moved copies of a StarParams."""
    (parsed,) = parse_directions([label])
    return parsed


def sobol_table(path: Path) -> tuple:
    """(the Sobol table's gait, parameter and SOBOL_COLUMNS, the preset it was computed with
    from its provenance sidecar, "" without one or without a preset in it); StudyArgumentError
    naming --sobol for a file that cannot be read (`cli.read_csv_file`), a table without
    those columns, or a sidecar that cannot be read, is not a JSON object or no longer
    describes the table (`read_provenance`: its SHA-256 differs, the table edited since, whose
    indices may no longer be that preset's; the message says how to use it without)."""
    table = cli.read_csv_file(path, "--sobol")
    columns = ["gait", "parameter", *SOBOL_COLUMNS]
    missing = [column for column in columns if column not in table.columns]
    if missing:
        raise cli.StudyArgumentError(f"--sobol {path}: not a Sobol table with columns "
                                     f"{', '.join(columns)} (no {', '.join(missing)})")
    if table.empty:  # a header alone left every row's S1 and ST empty (an audit, 2026-12)
        raise cli.StudyArgumentError(f"--sobol {path}: no rows (a header alone)")
    sidecar = provenance.sidecar_path(path)
    if not sidecar.exists():
        return _by_sensitivity_name(table[columns]), ""
    try:
        recorded = read_provenance(path)
    except OSError as error:  # a folder, no permission
        raise cli.StudyArgumentError(f"--sobol {path}: its provenance sidecar {sidecar} cannot "
                                     f"be read ({error.strerror or error})") from None
    except ValueError as error:  # not a JSON object, or a table edited since its sidecar
        raise cli.StudyArgumentError(f"--sobol {error}; remove {sidecar.name} to use the table "
                                     f"without its preset") from None
    model = recorded.get("model") or {}
    return _by_sensitivity_name(table[columns]), \
        model.get("preset", "") if isinstance(model, dict) else ""


def _by_sensitivity_name(table: pd.DataFrame) -> pd.DataFrame:
    """The Sobol table with its parameters named as the sensitivities name them: the sensitivity
    study writes an element by its actuator's number (actuator_gains[1] is A1, the command
    line's), the sensitivities by Python's index (actuator_gains[0]), and the join put A1's
    indices on A2's row (an audit, 2026-12)."""
    return table.assign(parameter=[identify.sensitivity_name(label)
                                   for label in table["parameter"]])


def elasticity_table(params: Sequence[StarParams], parameters: Sequence[str],
                     speeds: np.ndarray, derivatives: Dict[str, np.ndarray],
                     sobol: pd.DataFrame, sobol_preset: str) -> pd.DataFrame:
    """One row per instance × parameter: value, unit, the signed speed v (mm/s), dv/dp
    (`derivatives[label]`, (B,)), the elasticity (p / v)·dv/dp (0 for p = 0: `at_zero`), and the
    Sobol indices of (gait, field) where `sobol` has them (NaN otherwise)."""
    rows = []
    for b, p in enumerate(params):
        fired = set(Gait.parse(p.gait).actuators)
        for label in parameters:
            field, index = direction(label).field, direction(label).index
            value = direction(label).value(p)
            unit = column_unit(StarParams.columns()[field]) or "1"
            derivative = float(derivatives[label][b])
            rows.append({
                "gait": p.gait, "parameter": label, "field": field,
                "actuator": f"A{index + 1}" if index >= 0 else "",
                "fired": (index + 1 in fired) if index >= 0 else True,
                "value": value, "unit": unit, "signed_speed_mm_s": float(speeds[b]),
                "derivative": derivative,
                "derivative_unit": "mm/s" if unit == "1" else f"mm/s per {unit}",
                "elasticity": value / float(speeds[b]) * derivative,
                "at_zero": value == 0.0})
    table = pd.DataFrame(rows)
    table = table.merge(sobol, how="left", on=["gait", "parameter"])
    table["sobol_preset"] = sobol_preset
    return table


def finite_difference_check(params: Sequence[StarParams], labels: Sequence[str],
                            solver: SolverConfig, duration_s: float, arch: str) -> pd.DataFrame:
    """Central differences of whole runs at h, 2h and 4h, extrapolated
    (`taichi_star.sensitivity_check.extrapolated_difference`), of the signed speed, for every
    instance × label, in one batch at CHECK_NEWTON_TOL. h is each parameter's own step as
    `check_sensitivities` takes it (`difference_step`: the sensitivities' ε, 1e-4 of the value
    for most, larger for the two that barely move the robot, whose runs at 1e-4 differ by
    little more than their Newton noise). Columns gait, parameter, finite_difference."""
    tight = solver.replace(newton_tol=min(solver.newton_tol, CHECK_NEWTON_TOL))
    differences = whole_run_differences(params, duration_s, tight,
                                        [direction(label) for label in labels], OUTPUT, arch)
    return pd.DataFrame({"gait": [p.gait for _ in labels for p in params],
                         "parameter": [label for label in labels for _ in params],
                         "finite_difference": extrapolated_difference(
                             *differences.reshape(-1, 3).T)})


def plot_elasticities(csv_path, png_path) -> Path:
    """Two heatmaps sharing their columns, from an elasticities CSV: the elasticity of each
    gait's signed speed to each parameter (cell text: its value; "0·" for a parameter at 0,
    whose elasticity is 0 by definition), and below the Sobol ST of the same cells (grey where
    the parameter was not in the Sobol box)."""
    plt = cli.use_agg()
    from matplotlib.colors import SymLogNorm

    table = pd.read_csv(csv_path, **cli.NAMES_AS_WRITTEN)
    gaits = list(dict.fromkeys(table["gait"]))
    parameters = list(dict.fromkeys(table["parameter"]))
    grid = table.pivot(index="gait", columns="parameter", values="elasticity").loc[
        gaits, parameters]
    zero = table.pivot(index="gait", columns="parameter", values="at_zero").loc[
        gaits, parameters].astype(bool)
    total = table.pivot(index="gait", columns="parameter", values="ST").loc[gaits, parameters]
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(0.42 * len(parameters) + 2.5, 7.5),
                                      sharex=True, gridspec_kw={"height_ratios": [1, 1]})
    largest = max(float(np.nanmax(np.abs(grid.to_numpy()))), 1e-3)
    image = top.imshow(grid.to_numpy(dtype=float), cmap="RdBu_r", aspect="auto",
                       norm=SymLogNorm(linthresh=0.01, vmin=-largest, vmax=largest))
    fig.colorbar(image, ax=top, label="elasticity d ln|v| / d ln p", shrink=0.9)
    for i, gait in enumerate(gaits):
        for j, parameter in enumerate(parameters):
            value = grid.loc[gait, parameter]
            text = "0·" if zero.loc[gait, parameter] else (
                "0" if value == 0 else f"{value:.2g}")
            top.text(j, i, text, ha="center", va="center", fontsize=5.5,
                     color="w" if abs(value) > 1 else "k")  # dark cells beyond ±1
    top.set_yticks(range(len(gaits)), gaits)
    top.set_title("Elasticity of each gait's signed speed (exact sensitivities; 0·: parameter "
                  "at 0)" + (f"\n{cli.run_settings(csv_path)}" if cli.run_settings(csv_path)
                             else ""), fontsize=9)
    masked = np.ma.masked_invalid(total.to_numpy(dtype=float))
    cmap = plt.get_cmap("viridis").with_extremes(bad="0.85")
    image = bottom.imshow(masked, cmap=cmap, vmin=0, vmax=1, aspect="auto")
    fig.colorbar(image, ax=bottom, label="Sobol total index ST", shrink=0.9)
    for i, gait in enumerate(gaits):
        for j, parameter in enumerate(parameters):
            if np.isfinite(total.loc[gait, parameter]):
                bottom.text(j, i, f"{total.loc[gait, parameter]:.2f}", ha="center",
                            va="center", fontsize=5.5,
                            color="k" if total.loc[gait, parameter] > 0.5 else "w")
    preset = table["sobol_preset"].iloc[0]
    bottom.set_yticks(range(len(gaits)), gaits)
    bottom.set_xticks(range(len(parameters)), parameters, rotation=60, ha="right", fontsize=7)
    bottom.set_title(f"Sobol total index ST over the Sobol box ({preset or 'unknown'} preset; "
                     f"grey: not in the box)", fontsize=9)
    return cli.save_figure(fig, png_path, dpi=130)


def build_parser():
    parser = cli.StudyParser("elasticities", DESCRIPTION)
    parser.add_argument("--gaits", default="paper",
                        help=cli.GAITS_HELP)
    parser.add_argument("--parameters", default=None, metavar="NAME,...",
                        help="parameters to differentiate by, as simulate(sensitivities=...) "
                             "names them, an actuator by its Python index (actuator_gains[0] "
                             "is A1's) (default: every differentiable field and each "
                             "actuator's gain and delay, less component heights at 0; all: "
                             "every differentiable field)")
    parser.add_argument("--sobol", default=str(SOBOL_TABLE), metavar="CSV",
                        help="the Sobol indices to set beside (default a checkout's "
                             "results/sensitivity.csv)")
    parser.add_argument("--check", default=None, metavar="NAME,...",
                        help="also compare these parameters' derivatives with whole-run central "
                             "differences (<prefix>_check.csv; each must be non-zero; all: "
                             "every differentiable field)")
    parser.add_argument("--prefix", default="elasticities",
                        help="output file prefix (default elasticities)")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    gaits = cli.resolve_gaits(args.gaits, firing=True)
    base = cli.base_params(args)
    solver = cli.solver(args)
    parameters = (default_parameters(base) if args.parameters is None
                  else cli.sensitivity_parameters(args.parameters, "--parameters"))
    heights = [label for label in parameters if label in COMPONENT_HEIGHTS
               and direction(label).value(base) == 0.0]
    if heights:
        raise cli.StudyArgumentError(f"--parameters: {heights[0]} is 0 (the 2.5-D model off) "
                                     f"in this model; set the component heights with --set")
    if solver.precision != "f64":
        raise cli.StudyArgumentError("sensitivities need precision f64")
    checked = [] if args.check is None else cli.sensitivity_parameters(args.check, "--check")
    for label in checked:
        if label not in parameters:
            raise cli.StudyArgumentError(f"--check: {label} is not among the parameters")
        if direction(label).value(base) == 0.0:
            raise cli.StudyArgumentError(f"--check: {label} is 0 in this model; a relative "
                                         f"finite-difference step needs a non-zero value")
    sobol_path = Path(cli.committed_input(args.sobol, "--sobol", "sensitivity"))
    if not sobol_path.is_file():
        raise cli.StudyArgumentError(f"--sobol: no such file {sobol_path}")
    sobol, sobol_preset = sobol_table(sobol_path)
    if sobol_preset and sobol_preset != args.preset:
        # set beside them on purpose or not: said, as the table's column says it (it was
        # joined without a word; an audit, 2026-12)
        warnings.warn(f"--sobol {sobol_path}: its indices are of the {sobol_preset} preset, "
                      f"these elasticities of the {args.preset} preset (the column "
                      f"sobol_preset says so in the table; --preset {sobol_preset} gives "
                      f"elasticities of its model)", RuntimeWarning, stacklevel=2)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver,
                     extra={"gaits": gaits, "parameters": parameters, "output": OUTPUT,
                            "sobol_table": str(sobol_path.resolve()),
                            "sobol_table_sha256": hashlib.sha256(
                                sobol_path.read_bytes()).hexdigest(),
                            "sobol_preset": sobol_preset})
    params = [base.replace(gait=gait) for gait in gaits]
    duration_s = cli.duration_s(args, base.period)
    started = time.perf_counter()
    result = simulate(params, duration_s, solver, arch=args.arch, sensitivities=parameters,
                      progress=not args.no_progress)
    wall_s = time.perf_counter() - started
    if not (result.summary["status"] == "ok").all():
        failed = result.summary.loc[result.summary["status"] != "ok", "gait"].tolist()
        print(f"not ok: {', '.join(failed)} (their rows are NaN)")
    speeds = np.where(result.summary["status"] == "ok", result.summary[OUTPUT], np.nan)
    derivatives = {label: result.sensitivity(OUTPUT, label) for label in parameters}
    table = elasticity_table(params, parameters, speeds, derivatives, sobol, sobol_preset)
    table["cycles"] = args.cycles
    table["quick"] = args.quick  # --quick: QUICK_DURATION_S from rest instead of the cycles
    csv = out.write_csv(table, f"{args.prefix}.csv",
                        extra={"instances": len(params) * (1 + REPLICAS_PER_DIRECTION * len(parameters)),
                               "wall_s": round(wall_s, 1)})
    out.wrote(plot_elasticities(csv, out.path(f"{args.prefix}.png")))
    if checked:
        check = finite_difference_check(params, checked, solver, duration_s, args.arch)
        check = check.merge(table[["gait", "parameter", "derivative"]],
                            on=["gait", "parameter"])
        check["relative_difference"] = ((check["derivative"] - check["finite_difference"])
                                        / check["finite_difference"].abs())
        out.write_csv(check, f"{args.prefix}_check.csv",
                      extra={"relative_steps": {label: direction(label).relative_step
                                                for label in checked},
                             "newton_tol": min(solver.newton_tol, CHECK_NEWTON_TOL)})
        print(check.to_string(index=False))
    out.report()
    with pd.option_context("display.width", 160, "display.max_rows", 400):
        print(table.pivot(index="parameter", columns="gait", values="elasticity")
              .loc[parameters, gaits].round(4).to_string())
    return table
