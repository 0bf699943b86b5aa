"""Sensitivities against finite differences, for every differentiable parameter, both
integrators, damping on and off, fixed and adaptive steps.

    python -m studies sensitivity_check [--duration 0.2] [--gaits A1+A2,A1+A3]
                                        [--parameters all|NAME,...] [--out DIR] [--quick]

For each of the eight solver settings (implicit Euler or BDF2 × material damping off or
τ = 0.01 s × fixed 1-ms steps or adaptive steps held at 1 ms by dt_max, so that every moved run
takes the same steps as the sensitivities freeze) the paper robot (every delay at
10.5 ms, off the step grid: `OFF_GRID_DELAY_S`) runs `--duration` from rest
on each gait, differentiated by every differentiable parameter (each actuator's gain and
delay, every real field but the period), and `taichi_star.sensitivity_check.check_sensitivities`
compares each derivative of the displacement along x with Richardson-extrapolated central
differences of whole runs and with a Taylor test. The component heights, off (0) in the paper
robot, are checked in a ninth setting with the 2.5-D model on (implicit Euler, fixed steps).

Writes `sensitivity_check.csv` (one row per setting × gait × parameter: the columns of
`check_sensitivities`, status of the runs behind the row included, with the setting's
integrator, damping_time_s, stepping; rewritten after every setting, so that a killed run keeps
the settings it finished) and `sensitivity_check.png` (relative error against the differences'
own spread, per parameter; its title counts the rows it cannot draw), each with its provenance
sidecar. Every setting's parameters and the robot-steps of all of them together are checked
before the output folder is made. The summary counts every row as one of `ROW_KINDS`: a row
whose runs failed and one whose differences are exactly 0 but whose sensitivity is not are
failures of the check, counted apart.

--quick: 0.02 s, gait A1+A3, the parameters alpha and actuator_gains[0], implicit Euler with
fixed steps only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star import SolverConfig, StarParams, fewest_steps
from taichi_star.sensitivity_check import check_arguments, check_sensitivities, instance_runs

from . import cli

DESCRIPTION = ("Sensitivities against finite differences of whole runs for every "
               "differentiable parameter: Euler and BDF2, damping on and off, fixed and adaptive "
               "steps.")
OFF_GRID_DELAY_S = 10.5e-3
"""Every actuator's delay in the checked robot, s: ten and a half 1-ms steps. At 0 (the
paper's robot) the actuation profile's switch, whose fitted branches miss by 0.0064 1/m, lies
on a step end and the run jumps as a delay moves (`sensitivities.delay_on_step_grid`): no
derivative to check. Half a step off the grid keeps the switch between step ends; ten steps
more keep the differences' step (10⁻⁵ of the delay) above the runs' Newton noise (at half a
step alone, 5 ns, most delay rows were ill-conditioned)."""
HEIGHTS = {"hub_height": 0.05, "foam_height": 0.024, "actuator_height": 0.02}
"""The 2.5-D setting's component heights, m (the robot's hub and foams; an actuator strip)."""
HEIGHTS_SETTING = "euler/heights/fixed"
"""The one setting with the component heights on (the 2.5-D model), the only one in which they
have a derivative."""
DAMPING_TIME_S = 0.01
QUICK_DURATION_S = 0.02
QUICK_PARAMETERS = ("alpha", "actuator_gains[0]")
WELL_CONDITIONED_SPREAD = 1e-6
"""The largest spread of the differences (`difference_spread`) of a well-conditioned check."""
ROW_KINDS = ("well_conditioned", "ill_conditioned", "zero", "nonzero_at_zero", "failed")
"""What a row of the check is (`row_kinds`): well- or ill-conditioned (spread at most
WELL_CONDITIONED_SPREAD, or more or NaN); "zero", differences and sensitivity both exactly 0
(an actuator the gait never fires); "nonzero_at_zero", differences exactly 0 but the
sensitivity not (a failure of the check, which its absolute_error measures: its relative error
is inf and its spread NaN); "failed", a run behind the row did not finish ok (its status)."""


def settings(quick: bool):
    """(name, integrator, damping time, adaptive, heights) of each solver setting."""
    if quick:
        return [("euler/fixed", "euler", 0.0, False, False)]
    rows = [(f"{integrator}/{'damped' if damping else 'undamped'}/"
             f"{'adaptive' if adaptive else 'fixed'}", integrator, damping, adaptive, False)
            for integrator in ("euler", "bdf2") for damping in (0.0, DAMPING_TIME_S)
            for adaptive in (False, True)]
    return rows + [(HEIGHTS_SETTING, "euler", 0.0, False, True)]


def solver_of(integrator: str, adaptive: bool) -> SolverConfig:
    """The SolverConfig of one setting (at most 1-ms steps, adaptive or fixed)."""
    return SolverConfig(integrator=integrator, newton_tol=1e-12, adaptive=adaptive,
                        **({"error_tol": 1e-3, "dt_max": 1e-3} if adaptive else {}))


def row_kinds(table: pd.DataFrame) -> pd.Series:
    """The kind (`ROW_KINDS`) of each row of a check table (`check_sensitivities`' columns),
    every row exactly one: a failed run first, then exactly zero differences, then the
    differences' spread."""
    ok = table["status"].eq("ok")
    zero = ok & table["difference"].eq(0.0)
    return pd.Series(np.select(
        [~ok, zero & table["sensitivity"].ne(0.0), zero,
         table["difference_spread"] <= WELL_CONDITIONED_SPREAD],
        ["failed", "nonzero_at_zero", "zero", "well_conditioned"], "ill_conditioned"),
        index=table.index)


def summary_line(table: pd.DataFrame) -> str:
    """The rows of a check table counted by kind (`row_kinds`; the failures of the check
    named so), and the relative error of the well-conditioned ones."""
    kind = row_kinds(table)
    kinds = kind.value_counts().reindex(ROW_KINDS, fill_value=0)
    well = table.loc[kind == "well_conditioned", "relative_error"]
    errors = f", relative error max {well.max():.2g}, median {well.median():.2g}" \
        if len(well) else ""
    return (f"{len(table)} checks: {kinds['well_conditioned']} well-conditioned (spread <= "
            f"{WELL_CONDITIONED_SPREAD:g}){errors}; {kinds['ill_conditioned']} ill-conditioned; "
            f"{kinds['zero']} with differences and sensitivity exactly 0; failed: "
            f"{kinds['nonzero_at_zero']} with differences exactly 0 but a sensitivity not, "
            f"{kinds['failed']} whose runs did not finish ok")


def plot_check(csv_path, png_path) -> Path:
    """Relative error of each sensitivity against the finite differences' own spread (both
    log), one point per setting × gait × parameter, from the check CSV; the title counts the
    rows that log axes cannot show, by kind (`row_kinds`), and those whose error or spread is
    exactly 0."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    kinds = row_kinds(table)
    conditioned = kinds.isin(["well_conditioned", "ill_conditioned"])
    shown = table[conditioned & (table["relative_error"] > 0) & (table["difference_spread"] > 0)]
    fig, ax = plt.subplots(figsize=(7.0, 5.0))
    for setting, rows in shown.groupby("setting"):
        ax.scatter(rows["difference_spread"], rows["relative_error"], s=12, label=setting)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1e-5, color="k", lw=0.8, ls="--")
    ax.set_xlabel("spread of the finite differences |D(h) − D_R| / |D_R|")
    ax.set_ylabel("|sensitivity − D_R| / |D_R|")
    ax.set_title("Sensitivities against Richardson-extrapolated differences D_R\n"
                 "(dashed: 1e-5; points right of ~1e-5 are ill-conditioned checks)\n"
                 f"{len(shown)} of {len(table)} checks drawn; not drawn: "
                 f"{(kinds == 'failed').sum()} failed runs, "
                 f"{(kinds == 'nonzero_at_zero').sum()} non-zero sensitivities at zero "
                 f"differences, {(kinds == 'zero').sum()} zero at zero, "
                 f"{(conditioned.sum() - len(shown))} with an error or spread of 0",
                 fontsize=8)
    ax.legend(fontsize=6, ncol=2)
    return cli.save_figure(fig, png_path, dpi=130)


def check_parameters(setting: str, params, solver: SolverConfig, names, duration_s: float):
    """StudyArgumentError naming --parameters where `check_sensitivities` would refuse `names`
    for this setting's robots and solver (`check_arguments`), before anything runs: a
    component height outside the one setting that sets the heights, say."""
    try:
        check_arguments(params, solver, names, duration_s)
    except ValueError as error:
        why = (f"; a --parameters list is checked in every setting, and only {HEIGHTS_SETTING} "
               f"(not run with --quick) sets the component heights: --parameters all checks "
               f"them there" if any(name in HEIGHTS for name in names) else "")
        raise cli.StudyArgumentError(f"--parameters: in setting {setting}: {error}{why}") \
            from None


def build_parser():
    parser = cli.StudyParser("sensitivity_check", DESCRIPTION)
    parser.add_argument("--duration", type=float, default=0.2, quick=QUICK_DURATION_S,
                        help="simulated seconds from rest per run")
    parser.add_argument("--gaits", default="A1+A2,A1+A3", quick="A1+A3",
                        help=cli.GAITS_HELP)
    parser.add_argument("--parameters", default="all", quick=",".join(QUICK_PARAMETERS),
                        help="comma list of parameters as simulate's sensitivities take them "
                             "(an actuator by its Python index: actuator_gains[0] is A1's), "
                             "or all (every differentiable one)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    cli.check_positive(args.duration, "--duration")
    gaits = cli.resolve_gaits(args.gaits, firing=True)
    base = StarParams.preset("paper", actuator_delays=(OFF_GRID_DELAY_S,) * 8)
    # every setting's robots, solver and parameters, each checked before the output folder:
    # "all" is every differentiable field but the component heights, off in the paper robot,
    # and the heights alone in the setting that sets them
    plans = []
    for name, integrator, damping, adaptive, heights in settings(args.quick):
        names = cli.sensitivity_parameters(args.parameters, "--parameters",
                                           heights="only" if heights else "without")
        params = [base.replace(gait=gait, damping_time=damping, **(HEIGHTS if heights else {}))
                  for gait in gaits]
        solver = solver_of(integrator, adaptive)
        cli.check_run(f"--duration {args.duration:g} s", args.duration, solver)
        check_parameters(name, params, solver, names, args.duration)
        plans.append((name, integrator, damping, adaptive, params, solver, names))
    # the robot-steps of every setting's runs together, each setting's instance-runs at its
    # own fewest steps (adaptive ones at dt_max: a lower bound, as simulate's own estimate)
    runs = [(instance_runs(len(params), len(names)), solver)
            for *_, params, solver, names in plans]
    cli.check_robot_steps(
        f"--duration {args.duration:g} s ({sum(count for count, _ in runs):,} instance-runs in "
        f"{len(plans)} settings)",
        sum(count * fewest_steps(solver, args.duration, 0.0)[0] for count, solver in runs),
        cli.work_arch(args))
    out = cli.Output(args, argv or [], model={"preset": "paper", "params": base},
                     extra={"duration_s": args.duration, "gaits": gaits})
    tables = []
    for name, integrator, damping, adaptive, params, solver, names in plans:
        with cli.batch_work_told():  # told above for every setting: not again for each call
            table = check_sensitivities(params, args.duration, solver, names,
                                        progress=not args.no_progress)
        tables.append(table.assign(setting=name, integrator=integrator, damping_time_s=damping,
                                   stepping="adaptive" if adaptive else "fixed"))
        # after every setting: a run killed in a later one keeps those it finished
        csv = out.write_csv(pd.concat(tables, ignore_index=True), "sensitivity_check.csv")
        if not args.no_progress:
            print(f"  {name}: {summary_line(table)}", flush=True)
    table = pd.concat(tables, ignore_index=True)
    out.wrote(plot_check(csv, out.path("sensitivity_check.png")))
    out.report()
    print(f"all settings: {summary_line(table)}")
    return table
