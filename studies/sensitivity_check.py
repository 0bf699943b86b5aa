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
`check_sensitivities` with the setting's integrator, damping_time_s, stepping) and
`sensitivity_check.png` (relative error against the differences' own spread, per parameter),
each with its provenance sidecar.

--quick: 0.02 s, gait A1+A3, the parameters alpha and actuator_gains[0], implicit Euler with
fixed steps only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star import SolverConfig, StarParams
from taichi_star.sensitivity_check import check_sensitivities

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
DAMPING_TIME_S = 0.01
QUICK_DURATION_S = 0.02
QUICK_PARAMETERS = ("alpha", "actuator_gains[0]")


def settings(quick: bool):
    """(name, integrator, damping time, adaptive, heights) of each solver setting."""
    if quick:
        return [("euler/fixed", "euler", 0.0, False, False)]
    rows = [(f"{integrator}/{'damped' if damping else 'undamped'}/"
             f"{'adaptive' if adaptive else 'fixed'}", integrator, damping, adaptive, False)
            for integrator in ("euler", "bdf2") for damping in (0.0, DAMPING_TIME_S)
            for adaptive in (False, True)]
    return rows + [("euler/heights/fixed", "euler", 0.0, False, True)]


def solver_of(integrator: str, adaptive: bool) -> SolverConfig:
    """The SolverConfig of one setting (at most 1-ms steps, adaptive or fixed)."""
    return SolverConfig(integrator=integrator, newton_tol=1e-12, adaptive=adaptive,
                        **({"error_tol": 1e-3, "dt_max": 1e-3} if adaptive else {}))


def plot_check(csv_path, png_path) -> Path:
    """Relative error of each sensitivity against the finite differences' own spread (both
    log), one point per setting × gait × parameter, from the check CSV."""
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    shown = table[(table["relative_error"] > 0) & (table["difference_spread"] > 0)]
    fig, ax = plt.subplots(figsize=(7.0, 5.0))
    for setting, rows in shown.groupby("setting"):
        ax.scatter(rows["difference_spread"], rows["relative_error"], s=12, label=setting)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1e-5, color="k", lw=0.8, ls="--")
    ax.set_xlabel("spread of the finite differences |D(h) − D_R| / |D_R|")
    ax.set_ylabel("|sensitivity − D_R| / |D_R|")
    ax.set_title("Sensitivities against Richardson-extrapolated differences D_R\n"
                 "(dashed: 1e-5; points right of ~1e-5 are ill-conditioned checks)", fontsize=9)
    ax.legend(fontsize=6, ncol=2)
    return cli.save_figure(fig, png_path, dpi=130)


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
    gaits = cli.resolve_gaits(args.gaits)
    base = StarParams.preset("paper", actuator_delays=(OFF_GRID_DELAY_S,) * 8)
    # each setting's parameters: "all" is every differentiable field but the component
    # heights, off in the paper robot, and the heights alone in the setting that sets them
    parameters = {}
    for _, integrator, _, adaptive, heights in settings(args.quick):  # before the output folder
        parameters[heights] = cli.sensitivity_parameters(args.parameters, "--parameters",
                                                         heights="only" if heights else "without")
        cli.check_run(f"--duration {args.duration:g} s", args.duration,
                      solver_of(integrator, adaptive))
    out = cli.Output(args, argv or [], model={"preset": "paper", "params": base},
                     extra={"duration_s": args.duration, "gaits": gaits})
    tables = []
    for name, integrator, damping, adaptive, heights in settings(args.quick):
        extra = HEIGHTS if heights else {}
        params = [base.replace(gait=gait, damping_time=damping, **extra) for gait in gaits]
        try:
            table = check_sensitivities(params, args.duration, solver_of(integrator, adaptive),
                                        parameters[heights])
        except ValueError as error:
            raise cli.StudyArgumentError(str(error)) from None
        tables.append(table.assign(setting=name, integrator=integrator, damping_time_s=damping,
                                   stepping="adaptive" if adaptive else "fixed"))
        if not args.no_progress:
            print(f"  {name}: {len(table)} checks, median relative error "
                  f"{np.nanmedian(table['relative_error']):.2g}", flush=True)
    table = pd.concat(tables, ignore_index=True)
    csv = out.write_csv(table, "sensitivity_check.csv")
    out.wrote(plot_check(csv, out.path("sensitivity_check.png")))
    out.report()
    well = table[table["difference_spread"] <= 1e-6]
    print(f"well-conditioned checks (spread <= 1e-6): {len(well)} of {len(table)}, relative "
          f"error max {well['relative_error'].max():.2g}, median "
          f"{well['relative_error'].median():.2g}")
    return table
