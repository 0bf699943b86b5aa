"""Reinforcement learning: train a PPO agent (Stable-Baselines3) on the goal-reaching
environment and drive it to the planner's goals, judged as the planners are.

    python -m studies rl [--timesteps 30000] [--num-envs 16] [--seed 0]
                         [--max-episode-steps 16] [--distance 50] [--directions 7] [--far 0]
                         [--tolerance 5] [--max-cycles 25] [--settle-cycles 4]
                         [--stop-speed MM_S] [--settled] [--firing-cost 0.1]
                         [--firing-prior P] [--policy ZIP] [--compare PLAN_DIR]
                         [--preset paper|accurate|identified] [--set NAME=VALUE ...] [--dt S]
                         [--out DIR] [--quick]
    python -m studies rl --replot DIR

Training: `to_sb3(StarSwimmerVectorEnv(--num-envs))` (one Simulator; goals drawn at --distance
mm in a uniform direction, an episode ends within --tolerance mm of its goal at a period
boundary, with --stop-speed only at or below that speed, with --settled only after
--settle-cycles periods unfired (the robot has coasted there: the drive's judgement; the
observed times since firing then reach past that), or after --max-episode-steps actuation
periods; reward: progress in mm less --firing-cost mm per actuator fired), PPO with an MLP
policy and the hyperparameters `PPO_SETTINGS` (recorded in every sidecar), seeded by --seed,
torch on one thread, --timesteps robot-periods in all. --firing-prior P: the untrained policy
fires each actuator with probability P (its action layer's bias; SB3's own start is 1/2, which
leaves a whole period unfired to 1 in 256 of its tries).
Then the deterministic policy drives one robot per goal (--directions at --distance mm, 0°,
360/n°, ..., and --far mm behind: `planner.default_goals`) with
`taichi_star.envs.drive_policy`: each stops where the environment would end its episode, then
coasts --settle-cycles periods and is judged at rest, within --tolerance, as `plan`'s
controllers are (its own success, within the tolerance in passing, is the `terminated`
column; with --settled its episode's end is that judgement).

--compare PLAN_DIR sets a `plan` run's controllers beside it (its plan.csv and, where it ran
with --lookahead, lookahead.csv): the same goals, tolerance, settling, robot and step, checked
from its sidecar before training.

Writes into --out (default a fresh runs/rl/<timestamp>/), each table with its provenance
sidecar: `rl_training.csv` (per rollout of --num-envs × PPO_SETTINGS n_steps periods:
timesteps, wall_s, episodes that ended in it, success_rate (the share within the tolerance),
mean_return, mean_length in periods, capped_episodes: those with a capped Newton solve, told
in one line instead of a warning per robot), `rl.csv` (`taichi_star.envs.POLICY_COLUMNS`, mode
"ppo"), `rl_cycles.csv`, `rl_paths.csv`, `controllers.csv`
(`taichi_star.lookahead.CONTROLLER_COLUMNS`: PPO and, with --compare, the plan run's
controllers), `rl_policy.zip` (the trained model: `PPO.load`) and `rl.png` (the learning curve
and the paths, drawn from the CSVs).

--policy ZIP: drives the PPO policy an rl run saved (its rl_policy.zip) instead of training
one, after checking from that run's rl.csv sidecar that it was trained on this run's task
(--settled, --settle-cycles where settled, --stop-speed), step and robot; the goals, tolerance,
--max-cycles and --compare are this run's (held-out goals: other distances and directions).
No rl_training.csv or rl_policy.zip is written, and rl.png has no learning curve.

--replot DIR: draws DIR/rl.png again from DIR's rl_training.csv, rl_paths.csv and rl.csv (its
sidecar's period), nothing else run; the picture records this command.

--quick: dt = 5 ms, 4 robots, 64 timesteps of 4-period episodes, two goals, 2 cycles of
driving and one of settling.
"""

from __future__ import annotations

import hashlib
import io
import math
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

from taichi_star.envs import StarSwimmerVectorEnv, SwimmerTask, drive_policy, to_sb3
from taichi_star.lookahead import compare_controllers
from taichi_star.output import read_provenance
from taichi_star.planner import (PLAN_COLUMNS, SETTLE_CYCLES)
from taichi_star.provenance import write_atomic

from . import cli, provenance

DESCRIPTION = ("Train a PPO agent on the goal-reaching environment and drive it to the "
               "planner's goals, judged as the planners are.")
PPO_SETTINGS = {"n_steps": 32, "batch_size": 128, "n_epochs": 5, "learning_rate": 3e-4,
                "gamma": 0.95, "ent_coef": 0.01}
"""PPO's hyperparameters: short rollouts (32 periods of every robot), a discount that sees a
few periods ahead (the goals are a few to a dozen periods away), a little entropy to keep
trying gaits."""
QUICK_DT = 5e-3
QUICK_PPO = {"n_steps": 16, "batch_size": 64, "n_epochs": 1}
"""--quick's smaller rollouts: 4 robots × 16 periods, one epoch."""
TORCH_THREADS = 1
"""torch's threads: the simulation takes the cores; one thread keeps a seed's run the same."""


def build_parser():
    parser = cli.StudyParser("rl", DESCRIPTION)
    parser.add_argument("--timesteps", type=int, default=30000, quick=64,
                        help="robot-periods of training in all (default 30000)")
    parser.add_argument("--num-envs", type=int, default=16, quick=4,
                        help="robots trained together in one Simulator (default 16)")
    parser.add_argument("--seed", type=int, default=0, help="PPO's and the goals' seed")
    parser.add_argument("--max-episode-steps", type=int, default=16, quick=4,
                        help="actuation periods before a training episode is cut (default 16)")
    # --distance is the training goals' distance too, --tolerance the episodes' end
    cli.add_goal_flags(parser, directions=7, far_mm=0.0, quick_directions=2)
    parser.add_argument("--max-cycles", type=int, default=25, quick=2,
                        help="periods a driven robot may fire before it is stopped")
    parser.add_argument("--settle-cycles", type=int, default=SETTLE_CYCLES, quick=1,
                        help="periods a stopped robot coasts before it is judged at rest")
    parser.add_argument("--stop-speed", type=float, default=None,
                        help="mm/s: an episode ends within the tolerance only at or below this "
                             "speed (the robot must stop there; default none: reaching the "
                             "tolerance ends it)")
    parser.add_argument("--settled", action="store_true",
                        help="an episode ends within the tolerance only after --settle-cycles "
                             "periods unfired (the robot must coast to the goal, as the drive "
                             "judges it; default: reaching the tolerance ends it)")
    parser.add_argument("--firing-cost", type=float, default=SwimmerTask.firing_cost_mm,
                        help=f"mm of progress the reward takes per actuator fired (default "
                             f"{SwimmerTask.firing_cost_mm:g})")
    parser.add_argument("--firing-prior", type=float, default=None, metavar="P",
                        help="the untrained policy's probability of firing each actuator, in "
                             "(0, 1) (default SB3's: 1/2)")
    parser.add_argument("--policy", default=None, metavar="ZIP",
                        help="drive the policy an rl run saved (its rl_policy.zip) instead of "
                             "training one")
    parser.add_argument("--replot", default=None, metavar="DIR",
                        help="draw DIR/rl.png again from the run's CSVs in DIR, and nothing "
                             "else")
    parser.add_argument("--compare", default=None, metavar="PLAN_DIR",
                        help="a plan run (same goals, tolerance, robot, step) whose controllers "
                             "controllers.csv sets beside PPO")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser, quick=QUICK_DT)
    return parser


def check_like_this_run(flag: str, source, verb: str, robot_phrase: str, table: Path,
                        record: dict, checks, solver, base):
    """The run that wrote `table` (`record`: its sidecar) against this one, before any compute:
    each (name, its recorded value, this run's flag, its value) of `checks`, then the step and
    the robot; StudyArgumentError "<flag> <source>: <verb> with <name> <value>, this run's
    <its flag> <value>" (and "<verb> at dt ...", "<robot_phrase> whose ...") for the first that
    differs."""
    where = f"{flag} {source}"
    for name, made, own_flag, own in checks:
        if made != own:
            raise cli.StudyArgumentError(f"{where}: {verb} with {name} {made!r}, this run's "
                                         f"{own_flag} {own!r}")
    made_dt = (record.get("solver") or {}).get("dt")
    if made_dt != solver.dt:
        raise cli.StudyArgumentError(f"{where}: {verb} at dt {made_dt!r} s, this run at "
                                     f"{solver.dt!r} s")
    recorded, differing = cli.robot_differences(table, base, flag)
    if differing:
        raise cli.StudyArgumentError(f"{where}: {robot_phrase} whose {differing[0]} is "
                                     f"{recorded[differing[0]]}, this run's "
                                     f"{provenance.plain(base)[differing[0]]}")


def read_compared(folder: str, goals: np.ndarray, base, solver, tolerance: float,
                  settle_cycles: int) -> pd.DataFrame:
    """The controllers of the plan run in `folder` (plan.csv, and lookahead.csv where it ran
    with --lookahead), checked against this run before any compute: the same goals (to the
    CSV's 10 digits), and by plan.csv's sidecar the same tolerance, settling, step and robot;
    StudyArgumentError naming --compare otherwise."""
    tables = [cli.read_table(Path(folder) / "plan.csv", "--compare", PLAN_COLUMNS,
                             "a plan run's plan.csv")]
    if (Path(folder) / "lookahead.csv").is_file():
        tables.append(cli.read_table(Path(folder) / "lookahead.csv", "--compare", PLAN_COLUMNS,
                                     "a plan run's lookahead.csv"))
    for table in tables:
        for _, part in table.groupby("mode", sort=False):
            made = part[["goal_x_mm", "goal_y_mm"]].to_numpy(dtype=float)
            if made.shape != goals.shape or not np.allclose(made, goals, rtol=1e-9, atol=1e-9):
                raise cli.StudyArgumentError(f"--compare {folder}: its goals are not this run's "
                                             f"(--distance, --directions, --far)")
    try:
        record = read_provenance(Path(folder) / "plan.csv")
    except (OSError, ValueError) as error:
        raise cli.StudyArgumentError(f"--compare {folder}: its plan.csv's sidecar cannot be "
                                     f"read ({error})") from None
    details = record.get("details") or {}
    check_like_this_run("--compare", folder, "made", "made with a robot",
                        Path(folder) / "plan.csv", record,
                        [("tolerance_mm", details.get("tolerance_mm"), "--tolerance", tolerance),
                         ("settle_cycles", details.get("settle_cycles"), "--settle-cycles",
                          settle_cycles)], solver, base)
    return pd.concat(tables, ignore_index=True)


def read_policy(path: str, args, base, solver, since_fired_cap_s: float):
    """(the PPO model saved in `path`, its SHA-256), checked first against the record of the
    run that saved it (rl.csv's sidecar beside it): the task it was trained on (settled, the
    settling where settled, stop speed, the observation's cap on the time since firing), the
    step and the robot must be this run's; StudyArgumentError naming --policy otherwise."""
    policy = Path(path)
    if not policy.is_file():
        raise cli.StudyArgumentError(f"--policy {path}: no such file (give the rl_policy.zip of "
                                     f"an rl run)")
    try:
        record = read_provenance(policy.parent / "rl.csv")
    except (OSError, ValueError) as error:
        raise cli.StudyArgumentError(f"--policy {path}: the record of its run (rl.csv and its "
                                     f"sidecar beside it) cannot be read ({error}): the task it "
                                     f"was trained on is not known") from None
    trained = record.get("details") or {}
    # runs before the settled task recorded neither: they were not settled, capped at 10 s
    checks = [("settled", trained.get("settled", False), "--settled gives", args.settled),
              ("stop_speed_mm_s", trained.get("stop_speed_mm_s"), "--stop-speed gives",
               args.stop_speed)]
    if args.settled:
        checks.append(("settle_cycles", trained.get("settle_cycles"), "--settle-cycles gives",
                       args.settle_cycles))
    checks.append(("since_fired_cap_s",
                   trained.get("since_fired_cap_s", SwimmerTask.since_fired_cap_s),
                   "--settled and --settle-cycles (the observation's cap) give",
                   since_fired_cap_s))
    check_like_this_run("--policy", path, "trained", "trained on a robot",
                        policy.parent / "rl.csv", record, checks, solver, base)
    from stable_baselines3 import PPO

    data = policy.read_bytes()
    try:
        model = PPO.load(io.BytesIO(data), device="cpu")
    except Exception as error:  # noqa: BLE001 - SB3 raises what its zip and torch readers do
        raise cli.StudyArgumentError(f"--policy {path}: not a saved PPO policy ({error})"
                                     ) from None
    return model, hashlib.sha256(data).hexdigest()


def train(env_kwargs: dict, num_envs: int, timesteps: int, seed: int, settings: dict,
          firing_prior=None, keep=None, progress: bool = True):
    """(the trained PPO model, the training table: one row per rollout, `rl_training.csv`).
    firing_prior: None (SB3's start) or the untrained policy's probability of firing each
    actuator. `keep(model, table)`: called before each rollout but the first with the model
    updated from the rollouts so far and their table, so that an interrupted training keeps
    them (a Ctrl-C after half an hour lost all of it: an audit, 2026-12). `progress`: a bar of
    the timesteps trained (robot-periods)."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.logger import Logger
    from stable_baselines3.common.vec_env import VecMonitor

    torch.set_num_threads(TORCH_THREADS)
    envs = VecMonitor(to_sb3(StarSwimmerVectorEnv(num_envs, **env_kwargs)))
    started = time.perf_counter()
    rows, ended = [], []
    bar = None
    if progress:
        from tqdm.auto import tqdm
        bar = tqdm(total=timesteps, unit="period", desc="rl training")

    class Rollouts(BaseCallback):
        """Each episode's end as it comes; a row of them at each rollout's end."""

        def _on_step(self) -> bool:
            if bar is not None:
                bar.update(len(self.locals["dones"]))
            for done, info in zip(self.locals["dones"], self.locals["infos"]):
                if done:  # the info of the episode's last period, before the robot's reset
                    ended.append((info["episode"]["r"], info["episode"]["l"],
                                  not info["TimeLimit.truncated"], info["newton_capped"]))
            return True

        def _on_rollout_end(self):
            returns, lengths, reached, capped = (np.array(column, dtype=float) for column in
                                                 zip(*ended)) if ended else ([np.nan],) * 4
            rows.append({"timesteps": self.num_timesteps,
                         "wall_s": time.perf_counter() - started, "episodes": len(ended),
                         "success_rate": np.mean(reached), "mean_return": np.mean(returns),
                         "mean_length": np.mean(lengths),
                         "capped_episodes": int(np.nansum(capped))})
            ended.clear()
            if bar is not None:
                bar.set_postfix_str(f"success {rows[-1]['success_rate']:.2f}")

        def _on_rollout_start(self):
            # after the update from the rollouts so far: the policy their rows led to
            if keep is not None and rows:
                keep(self.model, pd.DataFrame(rows))

    model = PPO("MlpPolicy", envs, seed=seed, device="cpu", verbose=0, **settings)
    # no log folder (SB3's default logger makes one in the temporary folder)
    model.set_logger(Logger(folder=None, output_formats=[]))
    if firing_prior is not None:
        # the Bernoulli logits are the action layer's output, ~0 at SB3's start (its weights
        # are orthogonal with gain 0.01): the bias sets where every actuator starts
        with torch.no_grad():
            model.policy.action_net.bias.fill_(math.log(firing_prior / (1.0 - firing_prior)))
    with warnings.catch_warnings():
        # a policy trying gaits re-fires hot actuators, whose steps at 5 ms can end on a
        # capped Newton solve: counted per rollout (capped_episodes) and told once below
        # instead of a warning for every robot after each of its resets
        warnings.filterwarnings("ignore", message=r".*newton_capped", category=RuntimeWarning)
        try:
            model.learn(timesteps, callback=Rollouts())
        finally:
            if bar is not None:
                bar.close()
    envs.close()
    table = pd.DataFrame(rows)
    if table["capped_episodes"].sum():
        print(f"{table['capped_episodes'].sum()} of {table['episodes'].sum()} training "
              f"episodes had a capped Newton solve (rl_training.csv's capped_episodes): a "
              f"policy trying gaits re-fires hot actuators, which a smaller --dt resolves")
    return model, table


def plot_learning(curve, training: pd.DataFrame):
    """The learning curve on the axes `curve`: success rate and mean episode length against
    timesteps."""
    curve.plot(training["timesteps"], training["success_rate"], ".-", color="tab:blue")
    curve.set_xlabel("timesteps (robot-periods)")
    curve.set_ylabel("episodes within the tolerance", color="tab:blue")
    curve.set_ylim(-0.02, 1.02)
    length = curve.twinx()
    length.plot(training["timesteps"], training["mean_length"], ".-", color="tab:orange")
    length.set_ylabel("mean episode length (periods)", color="tab:orange")


def plot(training_csv, paths_csv, summary_csv, png_path) -> Path:
    """The learning curve (success rate and mean episode length against timesteps; none for
    a run of a saved policy, training_csv None) and the driven paths (goals as stars; driven
    solid, then the glide dotted up to where each robot is judged, run_cycles periods in (its
    sidecar's period): o reached at rest, x not), from the CSVs."""
    plt = cli.use_agg()
    paths, summary = pd.read_csv(paths_csv), pd.read_csv(summary_csv)
    period = read_provenance(summary_csv)["model"]["params"]["period"]
    if training_csv is None:
        fig, field = plt.subplots(figsize=(5.8, 4.6))
    else:
        fig, (curve, field) = plt.subplots(1, 2, figsize=(11, 4.6))
        plot_learning(curve, pd.read_csv(training_csv))
    for goal, part in paths.groupby("goal"):
        row = summary[summary["goal"] == goal].iloc[0]
        # the robots judged early glide on in the table until the last one is judged
        judged = int(np.abs(part["t_s"] - row["run_cycles"] * period).argmin())
        part = part.iloc[:judged + 1]
        driven = part[part["controlled"]]
        line, = field.plot(driven["x_mm"], driven["y_mm"], lw=1.2)
        colour = line.get_color()
        gliding = part[part["t_s"] >= driven["t_s"].iloc[-1]]
        field.plot(gliding["x_mm"], gliding["y_mm"], ":", lw=1.0, color=colour)
        field.plot(row["goal_x_mm"], row["goal_y_mm"], "*", ms=12, color=colour)
        field.plot(part["x_mm"].iloc[-1], part["y_mm"].iloc[-1], "o" if row["reached"] else "x",
                   color=colour)
    field.set_aspect("equal")
    field.set_xlabel("x (mm)")
    field.set_ylabel("y (mm)")
    field.set_title(f"PPO: {int(summary['reached'].sum())} of {len(summary)} goals reached at "
                    f"rest (driven solid, gliding dotted)", fontsize=10)
    fig.tight_layout()
    cli.write_figure(fig, png_path, dpi=130)
    plt.close(fig)
    return Path(png_path)


def replot(folder: str, argv) -> Path:
    """`plot` of the run in `folder` into folder/rl.png, the picture naming the command line
    `argv`; StudyArgumentError naming --replot for a folder without the run's CSVs, before
    anything is drawn."""
    for name in ("rl_paths.csv", "rl.csv"):
        if not (Path(folder) / name).is_file():
            raise cli.StudyArgumentError(f"--replot {folder}: no {name} there (give the folder "
                                         f"of an rl run)")
    training = Path(folder) / "rl_training.csv"  # none for a run of a saved policy
    provenance.record("rl", argv)  # the picture's study and command
    png = plot(training if training.is_file() else None, Path(folder) / "rl_paths.csv",
               Path(folder) / "rl.csv", Path(folder) / "rl.png")
    print(f"  wrote {png}")
    return png


TASK_FLAGS = {"goal_distance_mm": "--distance", "goal_tolerance_mm": "--tolerance",
              "max_episode_steps": "--max-episode-steps", "stop_speed_mm_s": "--stop-speed",
              "firing_cost_mm": "--firing-cost", "settle_cycles": "--settle-cycles",
              "since_fired_cap_s": "--settle-cycles"}
"""The flag of each SwimmerTask field that the study sets (`main`'s refusal names it): with
--settled the observation's cap is --settle-cycles + 1 periods."""


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if args.replot is not None:
        replot(args.replot, argv or [])
        return None
    for value, flag, lowest in ((args.timesteps, "--timesteps", 1),
                                (args.max_episode_steps, "--max-episode-steps", 1),
                                (args.max_cycles, "--max-cycles", 1),
                                (args.settle_cycles, "--settle-cycles", 0),
                                (args.seed, "--seed", 0)):
        if value < lowest:
            raise cli.StudyArgumentError(f"{flag} must be >= {lowest}, got {value}")
    cli.check_count(args.num_envs, "--num-envs", 1, cli.MAX_BATCH_SIZE)
    prior = args.firing_prior
    if prior is not None and not 0.0 < prior < 1.0:  # NaN too
        raise cli.StudyArgumentError(f"--firing-prior must be in (0, 1), got {prior}")
    goals, base, solver, frames = cli.driving(args)
    env_kwargs = {"params": base, "solver": solver, "goal_distance_mm": args.distance,
                  "goal_tolerance_mm": args.tolerance,
                  "max_episode_steps": args.max_episode_steps,
                  "stop_speed_mm_s": args.stop_speed, "firing_cost_mm": args.firing_cost,
                  "arch": args.arch}
    # settled, the observation tells a coast of settle_cycles periods from a shorter one
    since_fired_cap_s = (max(SwimmerTask.since_fired_cap_s,
                             (args.settle_cycles + 1) * base.period) if args.settled
                         else SwimmerTask.since_fired_cap_s)
    if args.settled:
        env_kwargs.update(settle_cycles=args.settle_cycles, since_fired_cap_s=since_fired_cap_s)
    try:
        SwimmerTask(**{name: value for name, value in env_kwargs.items()
                       if name not in ("params", "solver", "arch")})
    except ValueError as error:
        # SwimmerTask's messages begin with the field they refuse
        field = str(error).split(" ", 1)[0]
        raise cli.StudyArgumentError(f"{TASK_FLAGS[field]}: {error}") from None
    compared = None if args.compare is None else read_compared(
        args.compare, goals, base, solver, args.tolerance, args.settle_cycles)
    loaded, policy_sha256 = (None, None) if args.policy is None else read_policy(
        args.policy, args, base, solver, since_fired_cap_s)
    settings = {**PPO_SETTINGS, **(QUICK_PPO if args.quick else {})}
    if args.policy is None:
        cli.check_robot_steps(f"--timesteps {args.timesteps} periods of training",
                              args.timesteps * round(base.period / solver.dt),
                              cli.work_arch(args), base.n_nodes)
    training_settings = {"ppo": settings, "timesteps": args.timesteps,
                         "num_envs": args.num_envs, "seed": args.seed,
                         "max_episode_steps": args.max_episode_steps,
                         "firing_cost_mm": args.firing_cost, "firing_prior": prior}
    if args.policy is not None:  # nothing trained: the policy's own run records its training
        training_settings = dict.fromkeys(training_settings)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver,
                     extra={**training_settings,
                            "tolerance_mm": args.tolerance, "settle_cycles": args.settle_cycles,
                            "stop_speed_mm_s": args.stop_speed, "settled": args.settled,
                            "since_fired_cap_s": since_fired_cap_s,
                            "policy": (None if args.policy is None
                                       else str(Path(args.policy).resolve())),
                            "policy_sha256": policy_sha256,
                            "torch_threads": TORCH_THREADS,
                            "compared": (None if args.compare is None
                                         else str(Path(args.compare).resolve()))})
    if loaded is None:
        def keep(trained, table) -> Path:
            """The learning curve and the policy so far, each whole (`write_atomic`)."""
            policy = io.BytesIO()
            trained.save(policy)
            write_atomic(out.path("rl_policy.zip"), policy.getvalue(),
                         failure=lambda reason: cli.StudyOutputError(reason))
            out.wrote(out.path("rl_policy.zip"))
            return out.write_csv(table, "rl_training.csv")

        # kept after each update (an interrupted run keeps the rollouts it trained on) and
        # once trained, before the evaluation runs
        model, training = train(env_kwargs, args.num_envs, args.timesteps, args.seed, settings,
                                prior, keep=keep, progress=not args.no_progress)
        training_csv = keep(model, training)
    else:
        model, training_csv = loaded, None
    summary, cycles, path = drive_policy(
        lambda observation: model.predict(observation, deterministic=True)[0], goals, base,
        solver, args.tolerance, args.max_cycles, args.settle_cycles, frames, mode="ppo",
        stop_speed_mm_s=args.stop_speed, settled=args.settled,
        since_fired_cap_s=since_fired_cap_s, arch=args.arch)
    summary_csv = out.write_csv(summary, "rl.csv")
    out.write_csv(cycles, "rl_cycles.csv")
    paths_csv = out.write_csv(path, "rl_paths.csv")
    controllers = compare_controllers(pd.concat(
        [summary] if compared is None else [compared, summary], ignore_index=True))
    out.write_csv(controllers, "controllers.csv")
    out.wrote(plot(training_csv, paths_csv, summary_csv, out.path("rl.png")))
    out.report()
    with pd.option_context("display.width", 160, "display.max_columns", 20):
        print(summary.to_string(index=False))
        print(controllers.to_string(index=False))
    return summary
