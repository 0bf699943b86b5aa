"""Parameter sensitivity: the Cartesian product of lists or ranges, run as one chunked batch.

    python -m studies sweep --alpha 0.2:1.2:11 --added-mass 0,0.5,1,2 --youngs-modulus 2e6,5e6,1e7
                            [--jet-mode contract,always] [--gaits paper|all|A1,A1+A2] [--cycles 3]
                            [--param NAME=VALUES ...] [--preset paper|accurate] [--set NAME=VALUE]
                            [--out DIR] [--quick] [--resume] [--run-dir DIR]
                            [--workers N | --scheduler tcp://HOST:PORT] [--chunk-size N]
                            [--sensitivities NAME,...]

Values: a comma list (`0,0.5,1`) or a range `start:stop:n` (n points, both ends included) or
`start:stop:n:log` (geometric). `--param NAME=VALUES` sweeps any other StarParams field.
Writes `sweep.csv` (one row per instance: every parameter, whole-run and steady speeds, heading,
Newton statistics, status), the same table as `sweep.parquet` (typed, full precision, the
provenance in its metadata; `pandas.read_parquet`) and `sweep_<parameter>.png` for every swept
parameter: speed against the parameter, one line per gait, the other swept parameters held at
the value closest to the default.

`--sensitivities alpha,drag_perpendicular` adds every instance's derivatives of its speeds,
displacements and heading by those parameters (columns "d(OUTPUT)/d(PARAMETER)", exact for the
discrete scheme: `simulate(..., sensitivities=...)`), each costing two more instances' work;
a swept parameter among them gets its exact slope drawn through every point of its plot.

Resumable: every finished chunk is stored, verified, in the run store (`--run-dir`, default
`<out>/chunks/`). After a crash or a kill, the same command with `--out` of the killed run and
`--resume` skips the finished chunks (damaged ones are recomputed; a store holding a different
sweep is refused); `sweep.csv` is assembled from the store in input order.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from taichi_star import PER_ACTUATOR_FIELDS, StarParams
from taichi_star.batch import run_batch
from taichi_star.sensitivities import check_defined, instances_per_instance, parse_directions

from . import cli

DESCRIPTION = "Parameter sweep: Cartesian product of StarParams values, one chunked batch."

NAMED_FLAGS = {
    "alpha": "alpha",
    "added-mass": "added_mass_coeff",
    "youngs-modulus": "youngs_modulus",
    "limb-stiffness-ratio": "limb_stiffness_ratio",
    "drag-parallel": "drag_parallel",
    "drag-perpendicular": "drag_perpendicular",
    "cylinder-drag": "cylinder_drag",
    "cylinder-added-mass": "cylinder_added_mass_coeff",
    "period": "period",
    "jet-mode": "jet_mode",
}
"""Command-line flag -> StarParams field."""

CPU_CHUNK = 256
"""Default chunk size on the CPU: small enough that a kill costs little, large enough to keep
every core busy."""


def build_parser():
    parser = cli.StudyParser("sweep", DESCRIPTION)
    for flag, field in NAMED_FLAGS.items():
        forms = "list a,b,c" if cli.field_kind(field) is str else \
            "list a,b,c or range start:stop:n[:log]"
        parser.add_argument(f"--{flag}", dest=field, default=None, metavar="VALUES",
                            help=f"values of StarParams.{field} ({forms}; default: not swept, "
                                 f"the base model's)")
    parser.add_argument("--param", action="append", default=[], metavar="NAME=VALUES",
                        help="sweep any StarParams field, e.g. --param drag_parallel=0,0.01,0.1")
    parser.add_argument("--gaits", default="paper",
                        help=cli.GAITS_HELP)
    parser.add_argument("--max-instances", type=int, default=cli.MAX_INSTANCES,
                        help=f"refuse larger products (default and most {cli.MAX_INSTANCES})")
    parser.add_argument("--sensitivities", default=None, metavar="NAME,...",
                        help="also differentiate every instance's outputs by these parameters, "
                             "as simulate(sensitivities=...) names them, an actuator by its "
                             "Python index (actuator_gains[0] is A1's), or all (every "
                             "differentiable field, less the component heights where the model "
                             "has them at 0); each costs two more instances' work (default: "
                             "none)")
    cli.add_resume_flags(parser)
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser)
    cli.add_execution_flags(parser, chunk_size=CPU_CHUNK)
    return parser


def sweep_axes(args) -> dict:
    """The swept axes {field: values} from parsed arguments (validated, gait first)."""
    axes = {"gait": cli.resolve_gaits(args.gaits)}
    for flag, field in NAMED_FLAGS.items():
        text = getattr(args, field)
        if text is not None:
            axes[field] = cli.parse_field_values(text, f"--{flag}", field)
    for item in args.param:
        field = item.split("=", 1)[0].strip().replace("-", "_")
        if field in PER_ACTUATOR_FIELDS:
            # its eight values were read as eight values of an axis, each refused as "1 entry"
            # (an audit, 2026-12)
            raise cli.StudyArgumentError(
                f"--param {field}: a per-actuator field (eight values, A1..A8, a robot) is not an "
                f"axis of a sweep: give it to every instance with --set {field}=1,1,0.5,1,1,1,1,1,"
                f" or vary one actuator's value with `sensitivity --vary {field}[K]=LOW:HIGH`")
        name, values = cli.parse_assignment(item, "--param")
        # "given twice" where --gaits (a default) or a named flag gave the axis misled (an
        # audit, 2026-12)
        if name == "gait":
            raise cli.StudyArgumentError(f"--param gait: the gait axis is --gaits (e.g. "
                                         f"--gaits {item.split('=', 1)[1].strip()})")
        if name in axes:
            given_by = axis_flags(args, axes)[name]
            if given_by == f"--param {name}":
                raise cli.StudyArgumentError(f"--param {name}: given twice")
            raise cli.StudyArgumentError(f"--param {name}: swept by {given_by} already (give "
                                         f"its values once)")
        axes[name] = values
    for item in args.set:
        name, _ = cli.parse_assignment(item, "--set")
        if name in axes:
            raise cli.StudyArgumentError(f"--set {name}: swept as well (fix it or sweep it, "
                                         f"not both)")
    return axes


def axis_flags(args, axes) -> dict:
    """{field: the flag that gave its axis} of `sweep_axes`' axes, for the refusals."""
    named = {field: f"--{flag}" for flag, field in NAMED_FLAGS.items()
             if getattr(args, field) is not None}
    return {name: "--gaits" if name == "gait" else named.get(name, f"--param {name}")
            for name in axes}


def swept_parameters(table: pd.DataFrame):
    """{column: StarParams field} of the parameters (other than gait) that take more than one
    value in a sweep table."""
    return {column: name for name, column in StarParams.columns().items()
            if name != "gait" and column in table and table[column].nunique(dropna=False) > 1}


TANGENT_SHARE = 0.3
"""A slope's segment on a sweep's plot spans this share of the spacing to the nearest swept
value on each side of its point (so that neighbouring segments never meet)."""


def draw_slopes(ax, x: np.ndarray, y: np.ndarray, slopes: np.ndarray, colour) -> int:
    """Short segments through the points (x, y) with the exact slopes dy/dx of a sweep run with
    --sensitivities (`TANGENT_SHARE` of the nearest spacing each side), where all three are
    finite: the curve through the points should follow them. Returns how many were drawn."""
    drawn = 0
    for k in range(len(x)):
        gaps = np.abs(np.delete(x, k) - x[k])
        gaps = gaps[gaps > 0]
        if not (len(gaps) and np.isfinite([x[k], y[k], slopes[k]]).all()):
            continue
        half = TANGENT_SHARE * gaps.min()
        ax.plot([x[k] - half, x[k] + half], [y[k] - slopes[k] * half, y[k] + slopes[k] * half],
                "-", color=colour, lw=2.2, alpha=0.5)
        drawn += 1
    return drawn


def plot_sweep(csv_path, out: cli.Output, prefix: str = "sweep"):
    """One PNG per swept parameter from a sweep CSV: |speed| and signed speed against the
    parameter, one line per gait, other swept parameters at the value nearest the default;
    where the table has the speeds' derivatives by that parameter (--sensitivities), each
    point carries a short segment of its exact slope (`draw_slopes`)."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    defaults = StarParams()
    swept = swept_parameters(table)
    paths = []
    for name in swept:
        selection = table
        held = []
        for other in swept:
            if other == name:
                continue
            values = selection[other].unique()
            default = getattr(defaults, swept[other])
            if isinstance(default, str):
                pick = default if default in values else sorted(values)[0]
            else:
                pick = values[np.argmin(np.abs(values.astype(float) - default))]
            selection = selection[selection[other] == pick]
            field = swept[other]
            held.append(f"{field}={pick:g}" if not isinstance(pick, str) else f"{field}={pick}")
        fig, axes = plt.subplots(1, 2, figsize=(10, 4))
        categorical = not pd.api.types.is_numeric_dtype(selection[name])
        categories = sorted(selection[name].unique()) if categorical else None
        slopes_drawn = 0
        for gait, part in selection.groupby("gait", sort=False):
            part = part.sort_values(name)
            x = ([categories.index(v) for v in part[name]] if categorical
                 else part[name].to_numpy(dtype=float))
            ok = (part["status"] == "ok").to_numpy()
            for ax, column in zip(axes, ("speed_mm_s", "signed_speed_mm_s")):
                y = np.where(ok, part[column].to_numpy(dtype=float), np.nan)
                (line,) = ax.plot(x, y, "o-", label=gait, ms=3)
                slope = f"d({column})/d({swept[name]})"
                if not categorical and slope in part:
                    slopes_drawn += draw_slopes(ax, x, y, part[slope].to_numpy(dtype=float),
                                                line.get_color())
                bad = ~ok
                if bad.any():
                    ax.plot(np.asarray(x)[bad], np.zeros(bad.sum()), "rx")
        for ax, label in zip(axes, ("speed (mm/s)", "signed speed along forward (mm/s)")):
            ax.set_xlabel(cli.axis_label(name))
            ax.set_ylabel(label)
            if categorical:
                ax.set_xticks(range(len(categories)), categories)
            else:
                values = selection[name].to_numpy(dtype=float)
                if values.min() > 0 and values.max() / values.min() >= 20:
                    ax.set_xscale("log")
            ax.grid(alpha=0.3)
        axes[1].axhline(0.0, color="k", lw=0.6)
        axes[0].legend(fontsize=7)
        duration = table["duration_s"].iloc[0] if "duration_s" in table else math.nan
        settings = cli.run_settings(csv_path)
        fig.suptitle(f"speed vs {swept[name]} over {duration:g} s from rest"
                     + (f"; {settings}" if settings else "")
                     + (f" ({', '.join(held)})" if held else "")
                     + ("; x = failed" if (selection["status"] != "ok").any() else "")
                     + ("; short lines: exact slopes" if slopes_drawn else ""),
                     fontsize=9)
        fig.tight_layout()
        path = out.path(f"{prefix}_{swept[name]}.png")
        cli.write_figure(fig, path, dpi=120)
        plt.close(fig)
        paths.append(path)
    return paths


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if not 1 <= args.max_instances <= cli.MAX_INSTANCES:
        raise cli.StudyArgumentError(f"--max-instances must be in [1, {cli.MAX_INSTANCES}] (the "
                                     f"most instances a study runs), got {args.max_instances}")
    axes = sweep_axes(args)
    # Python's integers: NumPy's int64 product of four axes of 65,536 points wrapped to 0
    size = math.prod(len(v) for v in axes.values())
    if size > args.max_instances:
        raise cli.StudyArgumentError(
            f"the product has {size} instances, more than --max-instances {args.max_instances}")
    base = cli.base_params(args, axes)
    # checked before the grid is built: a swept period sets the longest and the shortest run
    solver = cli.solver(args, periods=axes.get("period", ()))
    parameters = ([] if args.sensitivities is None
                  else cli.sensitivity_parameters(args.sensitivities, "--sensitivities",
                                                  heights=cli.heights_in_all(base)))
    cli.tell_batch_work(args, solver, size, periods=axes.get("period", ()),
                        replicas=instances_per_instance(len(parameters)),
                        nodes=cli.mean_nodes(base, axes))
    grid = cli.param_product(axes, base=base, flags=axis_flags(args, axes))
    try:
        # before the output folder: where the grid's robots have no derivative (f32, a
        # component height at 0)
        check_defined(parse_directions(parameters), grid, solver)
    except ValueError as error:
        raise cli.StudyArgumentError(f"--sensitivities: {error}") from None
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver,
                     extra={"axes": axes, **({"sensitivities": parameters} if parameters else {})})
    run_dir = cli.run_store(args, out)
    with cli.executor(args, out) as executor, cli.batch_work_told():
        result = run_batch(grid, **cli.run_length(args), solver=solver, arch=args.arch,
                           chunk_size=cli.chunk_size(args, len(grid), executor.n_workers),
                           executor=executor, run_dir=run_dir, run_dir_flag="--run-dir",
                           resume=args.resume, progress=not args.no_progress,
                           sensitivities=parameters)
    table = result.summary
    if parameters:  # the same rows, in the same order
        table = pd.concat([table, result.sensitivities], axis=1)
    csv = out.write_csv(table, "sweep.csv")
    out.write_parquet(table, "sweep.parquet")
    out.wrote(*plot_sweep(csv, out))
    out.report()
    failed = (result.summary["status"] != "ok").sum()
    print(f"{len(result.summary)} instances, {failed} not ok")
    return table
