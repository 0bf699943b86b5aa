"""Throughput of the vector environment: simulated robot-seconds per wall second.

    python -m studies env_bench [--num-envs 64] [--steps 2] [--presets paper,accurate]
                                [--jacobians newton,chord] [--control-period S] [--dt S]
                                [--rounds 3] [--arch cpu|gpu] [--out DIR] [--quick]

For each preset (StarParams.preset and SolverConfig.preset of that name) and Jacobian mode
(SolverConfig.jacobian: "chord" reuses a step's first LU; same converged solution) builds
`StarSwimmerVectorEnv(num_envs)` (one Simulator), resets it with seed 0 and takes one untimed
step (the engine compiles on the first advance); then --rounds interleaved rounds each time
--steps steps of seeded random actions (each actuator fired with probability 1/2) of every
setting in turn, the environments going on from where the round before left them
(`profiling.interleaved_rounds`: the machine's drifts reach every setting alike). Writes
`env_bench.csv` (one row per preset and Jacobian: preset, jacobian, num_envs, steps,
control_period_s, dt_s, n_nodes, rounds, wall_s (the best round's), wall_s_median,
wall_s_rounds (every round's, ";"-separated), robot_seconds_per_s and robot_steps_per_s (of the
best round), robot_seconds_per_s_median, cores, load_average_1min (before the rounds),
cpu_model, arch) with its provenance sidecar (`.csv.json`) into --out (default a fresh
runs/env_bench/<timestamp>/). robot_steps_per_s counts steps of dt_s, so it is NaN for a solver
with adaptive steps (the accurate preset's), which take steps of their own length: counted in
1-ms steps it was about 11 times the steps taken (an audit, 2026-12). Until 2026-12 each
setting was timed once, one after the other (an audit).

--quick: 4 environments, one 0.2-s step at dt = 5 ms, one round.

The robot-steps of every setting together are refused past the library's limit, or estimated
when long, before any environment is built.
"""

from __future__ import annotations

import math
import os

import numpy as np
import pandas as pd

from taichi_star import JACOBIANS, PRESETS, SolverConfig, StarParams, fewest_steps
from taichi_star.envs import StarSwimmerVectorEnv, control_period
from taichi_star.profiling import interleaved_rounds
from taichi_star.provenance import cpu_model
from taichi_star.runtime import check_batch_memory
from taichi_star.timegrid import weighted_nodes

from . import cli

DESCRIPTION = "Vector environment throughput: simulated robot-seconds per wall second."
QUICK_NUM_ENVS = 4
QUICK_STEPS = 1
QUICK_CONTROL_PERIOD_S = 0.2
QUICK_DT = 5e-3


def measure(settings, num_envs: int, steps: int, control_period_s=None, arch: str = "cpu",
            rounds: int = 1) -> list:
    """The rows of env_bench.csv (see the module docstring), one per (preset, solver) of
    `settings`: the robots of each preset stepped with its solver, timed in `rounds`
    interleaved rounds."""
    built = []

    def prepare(preset: str, solver: SolverConfig):
        envs = StarSwimmerVectorEnv(num_envs, params=StarParams.preset(preset), solver=solver,
                                    control_period_s=control_period_s, arch=arch,
                                    max_episode_steps=rounds * steps + 2)
        envs.reset(seed=0)
        envs.action_space.seed(0)
        envs.step(envs.action_space.sample())  # compiles the engine
        built.append(envs)

    def timed(index: int):
        envs = built[index]
        for _ in range(steps):
            envs.step(envs.action_space.sample())

    load = []
    _, times, _ = interleaved_rounds(
        [lambda index=index: timed(index) for index in range(len(settings))], rounds,
        [lambda preset=preset, solver=solver: prepare(preset, solver)
         for preset, solver in settings],
        before_rounds=lambda: load.append(os.getloadavg()[0]))
    rows = []
    for index, (preset, solver) in enumerate(settings):
        period = built[index].control_period_s
        robot_seconds = num_envs * steps * period
        wall = float(times[:, index].min())
        rows.append({"preset": preset, "jacobian": solver.jacobian, "num_envs": num_envs,
                     "steps": steps, "control_period_s": period, "dt_s": solver.dt,
                     "n_nodes": built[index].simulator.n_nodes, "rounds": rounds,
                     "wall_s": wall, "wall_s_median": float(np.median(times[:, index])),
                     "wall_s_rounds": ";".join(f"{t:.6g}" for t in times[:, index]),
                     "robot_seconds_per_s": robot_seconds / wall,
                     "robot_seconds_per_s_median": robot_seconds / np.median(times[:, index]),
                     "robot_steps_per_s": (math.nan if solver.adaptive
                                           else robot_seconds / solver.dt / wall),
                     "cores": os.cpu_count(), "load_average_1min": load[0],
                     "cpu_model": cpu_model(), "arch": arch})
    return rows


def build_parser():
    parser = cli.StudyParser("env_bench", DESCRIPTION)
    cli.add_dt_flag(parser, quick=QUICK_DT, jacobian=False)
    parser.add_argument("--num-envs", type=int, default=64, quick=QUICK_NUM_ENVS,
                        help=f"robots in the vector env, at most {cli.MAX_BATCH_SIZE}")
    parser.add_argument("--steps", type=int, default=2, quick=QUICK_STEPS, help="timed steps")
    parser.add_argument("--presets", default="paper,accurate",
                        help=f"comma list of presets from {','.join(PRESETS)} (default "
                             f"paper,accurate)")
    parser.add_argument("--jacobians", default="newton",
                        help=f"comma list of Jacobian modes, {' and/or '.join(JACOBIANS)} "
                             f"(default newton)")
    parser.add_argument("--control-period", type=float, default=None,
                        quick=QUICK_CONTROL_PERIOD_S,
                        help="control period, s (none: the actuation period, 3.15)")
    parser.add_argument("--rounds", type=int, default=3, quick=1,
                        help="interleaved rounds, each timing every setting's --steps in turn "
                             "(default 3)")
    return parser


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    presets = cli.parse_choices(args.presets, "--presets", PRESETS)
    jacobians = cli.parse_choices(args.jacobians, "--jacobians", JACOBIANS)
    cli.check_count(args.num_envs, "--num-envs", 1, cli.MAX_BATCH_SIZE)
    if args.steps < 1:
        raise cli.StudyArgumentError(f"--steps must be >= 1, got {args.steps}")
    cli.check_count(args.rounds, "--rounds", 1, cli.MAX_REPEATS)
    solvers = {}
    parts = []  # (robot-steps, nodes) of each setting
    for preset in presets:
        for jacobian in jacobians:
            try:
                solvers[preset, jacobian] = SolverConfig.preset(
                    preset, jacobian=jacobian, **({} if args.dt is None else {"dt": args.dt}))
            except ValueError as error:
                raise cli.StudyArgumentError(f"--dt: {error}") from None
            try:
                period = control_period(StarParams.preset(preset), solvers[preset, jacobian],
                                        args.control_period)
            except ValueError as error:
                raise cli.StudyArgumentError(f"--control-period: {error}") from None
            # every round's timed steps and the one that compiles, one control period each
            duration = (args.rounds * args.steps + 1) * period
            cli.check_run(f"--rounds {args.rounds} × --steps {args.steps} (+1 compiling) of "
                          f"--control-period {period:g} s ({duration:.3g} s)", duration,
                          solvers[preset, jacobian])
            steps, _ = fewest_steps(solvers[preset, jacobian], duration, 0.0)
            parts.append((args.num_envs * steps, StarParams.preset(preset).n_nodes))
    # each setting's steps checked above; all settings' robots together refused or estimated
    # here (--num-envs 65536 --steps 50000, 1.03e13 robot-steps, started without a word: an
    # audit, 2026-12), before the memory (whose refusal depends on what the machine has free)
    cli.check_robot_steps(f"--num-envs {args.num_envs} × --rounds {args.rounds} × --steps "
                          f"{args.steps} (+1 compiling) × {len(solvers)} preset and Jacobian "
                          f"setting(s)", sum(count for count, _ in parts), cli.work_arch(args),
                          weighted_nodes(parts))
    for preset in presets:
        try:  # a million robots' engine: 116 GiB, failed after two minutes (an audit)
            check_batch_memory([StarParams.preset(preset)] * args.num_envs,
                               solvers[preset, jacobians[0]].precision, args.arch)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--num-envs: {error}") from None
    out = cli.Output(args, argv or [], model={"presets": presets},
                     solver={f"{preset}, {jacobian}": solver
                             for (preset, jacobian), solver in solvers.items()},
                     extra={"jacobians": jacobians, "num_envs": args.num_envs,
                            "steps": args.steps})
    with cli.batch_work_told():  # told above for the whole run: not again for each step
        rows = measure([(preset, solver) for (preset, _), solver in solvers.items()],
                       args.num_envs, args.steps, args.control_period, args.arch, args.rounds)
    for row in rows:
        steps_rate = row["robot_steps_per_s"]
        print(f"{row['preset']}, {row['jacobian']}: {row['robot_seconds_per_s']:.1f} robot-s "
              f"per wall s (best of {args.rounds})"
              + ("" if math.isnan(steps_rate) else f" ({steps_rate:,.0f} robot-steps/s)"))
    table = pd.DataFrame(rows)
    out.write_csv(table, "env_bench.csv")
    out.report()
    return table
