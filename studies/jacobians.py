"""Jacobians: the Newton Jacobian modes' speed against the solver's error, over a cycle of the
five Fig. 4c gaits.

    python -m studies jacobians [--batch 512] [--modes newton:1e-10,lagged:1e-10,...]
                                [--rounds 2] [--duration 3.15] [--out DIR] [--quick]

The five gaits repeated to --batch instances from rest, simulated for --duration (default one
period) with the paper preset's fixed 1-ms implicit Euler steps, once per configuration
(`SolverConfig.jacobian` and `newton_tol`, "mode:tol") and round; each round runs every
configuration back to back, so the rounds interleave them, and a configuration's time is its
best round's. The solver's error of a configuration is measured against a reference run of
the same batch with Newton's Jacobian at newton_tol 1e-13 m (timed like the others): the
largest difference of a final node coordinate (`position_error_m`) and of a displacement
(`displacement_error_mm`). The error Newton leaves at each step is below newton_tol: far
below with Newton's Jacobian, and below in every step measured with the chord's and the lagged
one (`SolverConfig.newton_tol`); were each step's error newton_tol, they would add up to at
most steps × newton_tol (`error_bound_m`, an envelope measured against, not a proven bound).

Writes `jacobians.csv` (one row per configuration, the reference included; `same_bits_as_default`:
whether the final positions equal those of the default solver, Newton's Jacobian at
1e-10 m, bit for bit; `speedup_vs_default`: the default's best time over this one's) and
`jacobians.png` (the position error against robot-steps/s).

The robot-steps of every configuration, round and warm-up together are refused past the
library's limit, or estimated when long, before the batch is built.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from taichi_star import JACOBIANS, SolverConfig, StarParams, fewest_steps, simulate
from taichi_star.experiment import PAPER_GAITS
from taichi_star.profiling import interleaved_rounds

from . import cli

DESCRIPTION = ("Newton Jacobian modes (newton, chord, lagged): speed against the solver's "
               "error over a cycle of the Fig. 4c gaits.")

DEFAULT_MODES = "newton:1e-10,chord:1e-10,lagged:1e-10,lagged:1e-11,lagged:1e-12"
REFERENCE = ("newton", 1e-13)
"""The reference configuration: Newton's Jacobian, converged to 1e-13 m (its updates contract
quadratically, so its own error is far below that)."""
DEFAULT = (SolverConfig().jacobian, SolverConfig().newton_tol)


def build_parser():
    parser = cli.StudyParser("jacobians", DESCRIPTION, archs=("cpu",))
    parser.add_argument("--modes", default=DEFAULT_MODES, quick="newton:1e-10,lagged:1e-10",
                        help=f"comma list of MODE:TOL configurations, MODE one of "
                             f"{', '.join(JACOBIANS)} and TOL Newton's tolerance, m (the "
                             f"reference, {REFERENCE[0]}:{REFERENCE[1]:g}, and SolverConfig's "
                             f"own, {DEFAULT[0]}:{DEFAULT[1]:g}, are always run)")
    parser.add_argument("--batch", type=int, default=512, quick=5,
                        help=f"instances (the five gaits repeated; at most {cli.MAX_BATCH_SIZE})")
    parser.add_argument("--duration", type=float, default=StarParams().period, quick=0.05,
                        help="simulated seconds per run")
    parser.add_argument("--rounds", type=int, default=2, quick=1,
                        help=f"interleaved rounds; a configuration's time is its best round's (at "
                             f"most {cli.MAX_REPEATS})")
    return parser


def parse_modes(text: str):
    """[(jacobian, newton_tol)] from "mode:tol,...", the default and the reference added (the
    reference last), each checked by SolverConfig (StudyArgumentError naming --modes)."""
    configurations = []
    # a configuration listed twice runs once (as the default and the reference do)
    for item in cli.parse_values(text, "--modes", str, repeats=True):
        mode, _, tol = item.partition(":")
        try:
            tolerance = float(tol)
        except ValueError:
            raise cli.StudyArgumentError(
                f"--modes: {item!r} is not MODE:TOL (MODE one of {', '.join(JACOBIANS)}, TOL "
                f"Newton's tolerance in m, e.g. lagged:1e-10)") from None
        try:
            SolverConfig(jacobian=mode, newton_tol=tolerance)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--modes: {item!r}: {error}") from None
        configurations.append((mode, tolerance))
    ordered = [DEFAULT] + [c for c in configurations if c not in (DEFAULT, REFERENCE)]
    return list(dict.fromkeys(ordered)) + [REFERENCE]


def check_args(args):
    cli.check_count(args.batch, "--batch", 1, cli.MAX_BATCH_SIZE)
    cli.check_count(args.rounds, "--rounds", 1, cli.MAX_REPEATS)
    dt = SolverConfig().dt
    if not dt <= args.duration <= 100.0:
        raise cli.StudyArgumentError(f"--duration must be in [{dt:g}, 100] s, got "
                                     f"{args.duration!r}")


def check_whole_run(args, configurations):
    """Refuse or estimate (`cli.check_steps`) the robot-steps of the whole run before the batch
    is built: every configuration's one-step warm-up and its --rounds runs of --duration, each
    of --batch instances (no call reached the warning alone: --batch 65536 --duration 100
    started 3.9e10 robot-steps without a word; an audit, 2026-12)."""
    robot_steps = args.batch * sum(
        args.rounds * fewest_steps(SolverConfig(jacobian=mode, newton_tol=tol), args.duration,
                                   0.0)[0] + 1 for mode, tol in configurations)
    cli.check_robot_steps(f"--batch {args.batch} × {len(configurations)} configurations × "
                          f"(--rounds {args.rounds} of --duration {args.duration:g} s + a "
                          f"one-step warm-up)", robot_steps, cli.work_arch(args))


def final_state(result, mode: str, tol: float):
    """(final node positions (B, N, 2) m, summary) of a configuration's run (`result`, its
    shapes recorded); RuntimeError naming the configuration if an instance failed (its time
    would not be valid)."""
    failed = result.summary[result.summary["status"] != "ok"]
    if len(failed):
        raise RuntimeError(f"{mode}:{tol:g}: instance {failed.index[0]} "
                           f"{failed['status'].iloc[0]}; its time would not be valid")
    return result.shapes[-1], result.summary


def jacobians_table(params, duration: float, configurations, rounds: int,
                    progress: bool = True) -> pd.DataFrame:
    """One row per configuration: best wall time, robot-steps/s, Newton iterations and
    factorisations per solve, the errors against the reference (the last configuration).
    The configurations' runs interleaved in `rounds` rounds (`profiling.interleaved_rounds`),
    each after a one-step call: the engine is the same for every mode (the mode is loaded, not
    compiled), so the first compiles it and the others load their mode."""
    solvers = [SolverConfig(jacobian=mode, newton_tol=tol) for mode, tol in configurations]
    calls = [lambda solver=solver: simulate(params, duration, solver, record_interval_s=duration,
                                            record_shapes=True, progress=False)
             for solver in solvers]
    warmups = [lambda solver=solver: simulate(params, solver.dt, solver, progress=False)
               for solver in solvers]

    def report(round_index: int, index: int, wall: float):
        mode, tol = configurations[index]
        print(f"round {round_index + 1}, {mode}:{tol:g}: {wall:.2f} s", flush=True)

    results, times, _ = interleaved_rounds(calls, rounds, warmups,
                                           progress=report if progress else None)
    best = dict(zip(configurations, times.min(axis=0)))
    shapes, summaries = {}, {}
    for configuration, result in zip(configurations, results):
        shapes[configuration], summaries[configuration] = final_state(result, *configuration)
    reference = configurations[-1]
    steps = int(summaries[reference]["steps"].iloc[0])
    displacement = ["displacement_x_mm", "displacement_y_mm"]
    rows = []
    for configuration in configurations:
        summary = summaries[configuration]
        mode, tol = configuration
        rows.append({
            "jacobian": mode, "newton_tol_m": tol, "reference": configuration == reference,
            "batch_size": len(params), "steps": steps, "wall_s": best[configuration],
            "robot_steps_per_s": len(params) * steps / best[configuration],
            "newton_iterations_mean": float(summary["newton_iterations_mean"].mean()),
            "factorisations_mean": float(summary["factorisations_mean"].mean()),
            "position_error_m": float(np.abs(shapes[configuration] - shapes[reference]).max()),
            "displacement_error_mm": float(np.abs(
                summary[displacement].to_numpy() - summaries[reference][displacement].to_numpy()
            ).max()),
            "error_bound_m": steps * tol,
            "same_bits_as_default": bool(np.array_equal(shapes[configuration], shapes[DEFAULT])),
        })
    table = pd.DataFrame(rows)
    table["speedup_vs_default"] = best[DEFAULT] / table["wall_s"]
    return table


def plot_jacobians(csv_path, png_path):
    plt = cli.use_agg()
    table = pd.read_csv(csv_path)
    fig, ax = plt.subplots(figsize=(7, 4.8))
    colours = {"newton": "tab:blue", "chord": "tab:green", "lagged": "tab:red"}
    for row in table[~table["reference"]].itertuples():
        ax.scatter(row.robot_steps_per_s, row.position_error_m,
                   color=colours.get(row.jacobian, "k"), zorder=3)
        ax.annotate(f"{row.jacobian}, {row.newton_tol_m:g} m", (row.robot_steps_per_s,
                                                                  row.position_error_m),
                    textcoords="offset points", xytext=(6, 4), fontsize=8)
    ax.set_yscale("log")
    ax.set_xlabel("robot-steps/s (best of the rounds)")
    ax.set_ylabel("largest final position error vs Newton at 1e-13 m (m)")
    ax.grid(alpha=0.3, which="both")
    batch, steps = int(table["batch_size"].iloc[0]), int(table["steps"].iloc[0])
    ax.set_title(f"Newton Jacobian modes: B = {batch}, five Fig. 4c gaits, {steps} steps of "
                 f"1 ms", fontsize=9)
    return cli.save_figure(fig, png_path)


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    check_args(args)
    configurations = parse_modes(args.modes)
    # every round simulates the batch once per configuration (the warm-ups' one step each
    # aside): counted before the batch is built, which took a minute at the most --batch
    cli.check_instances(
        args.batch * args.rounds * len(configurations),
        f"--batch {args.batch} × --rounds {args.rounds} × {len(configurations)} configurations "
        f"(--modes, with the default and the reference)")
    check_whole_run(args, configurations)
    params = cli.paper_gaits_batch(args.batch)
    out = cli.Output(args, argv or [], model={"preset": "paper", "gaits": list(PAPER_GAITS),
                                              "batch_size": args.batch},
                     solver=SolverConfig())
    with cli.batch_work_told():  # told by `check_whole_run`: not again for each call
        table = jacobians_table(params, args.duration, configurations, args.rounds,
                                progress=not args.no_progress)
    csv_path = out.write_csv(table, "jacobians.csv")
    out.wrote(plot_jacobians(csv_path, out.path("jacobians.png")))
    out.report()
    return table
