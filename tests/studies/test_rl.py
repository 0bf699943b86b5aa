"""The rl study: a PPO agent trained on the environment (--quick), driven to the goals and
judged as the planners; the policy it saves is the one that drove; its flags and a plan run
of other settings are refused before any compute. Needs stable-baselines3 (the `rl` extra;
CI installs it where the machine keeps a CPU build of torch), skipped without it."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star.envs import POLICY_COLUMNS, POLICY_CYCLE_COLUMNS, drive_policy
from taichi_star.lookahead import CONTROLLER_COLUMNS

from studies.__main__ import main as studies_main

pytest.importorskip("stable_baselines3")

QUICK = ["--quick", "--no-progress"]
COMPARED = "results/plan_lookahead"
"""A committed plan run: 7 goals at 50 mm, tolerance 5 mm, 4 cycles of settling, dt 5 ms."""
POLICY = "results/rl_settled_longer/rl_policy.zip"
"""A committed policy, trained with --settled (4 cycles) at dt 5 ms on the paper robot."""


@pytest.mark.slow
def test_quick_run_trains_drives_and_saves_the_policy_that_drove(tmp_path, monkeypatch):
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path / "sb3"))  # none is made: checked below
    from stable_baselines3 import PPO

    assert studies_main(["rl", *QUICK, "--out", str(tmp_path / "out")]) == 0
    out = tmp_path / "out"
    training = pd.read_csv(out / "rl_training.csv")
    # 64 timesteps in rollouts of 4 robots x 16 periods: one rollout, 16 episodes of 4
    assert training["timesteps"].tolist() == [64] and training["episodes"].tolist() == [16]
    assert training["mean_length"].tolist() == [4.0]
    assert training["capped_episodes"].tolist() == [0]
    summary = pd.read_csv(out / "rl.csv")
    assert list(summary.columns) == POLICY_COLUMNS and (summary["mode"] == "ppo").all()
    assert len(summary) == 2 and list(pd.read_csv(out / "controllers.csv").columns) \
        == CONTROLLER_COLUMNS
    cycles = pd.read_csv(out / "rl_cycles.csv")
    assert list(cycles.columns) == POLICY_CYCLE_COLUMNS
    # the saved policy, driven again to the same goals, fires the same gaits, bit for bit
    model = PPO.load(out / "rl_policy.zip", device="cpu")
    _, again, _ = drive_policy(lambda obs: model.predict(obs, deterministic=True)[0],
                               summary[["goal_x_mm", "goal_y_mm"]].to_numpy(),
                               taichi_star.StarParams.preset("paper"),
                               taichi_star.SolverConfig(dt=5e-3), max_cycles=2, settle_cycles=1,
                               mode="ppo")
    assert again["gait"].tolist() == cycles["gait"].tolist()
    np.testing.assert_allclose(again["x_mm"], cycles["x_mm"], rtol=1e-9)  # the CSV's digits
    sidecar = json.loads((out / "rl.csv.json").read_text())
    assert sidecar["details"]["ppo"]["n_steps"] == 16 and sidecar["details"]["timesteps"] == 64
    assert (out / "rl.png").stat().st_size > 1000 and not (tmp_path / "sb3").exists()


@pytest.mark.slow
def test_an_interrupted_training_keeps_the_rollouts_it_finished(tmp_path, monkeypatch, capsys):
    """A Ctrl-C after half an hour of training left nothing (an audit, 2026-12): the learning
    curve and the policy are kept after each update. Stopped in the second of two quick
    rollouts (64 periods each), the first rollout's row and the policy updated from it stay,
    whole, and the policy loads."""
    from stable_baselines3 import PPO

    from taichi_star.envs import StarSwimmerVectorEnv

    steps = []
    step = StarSwimmerVectorEnv.step

    def interrupted(self, actions):
        steps.append(1)
        if len(steps) > 20:  # a rollout is 16 steps of the 4 robots
            raise KeyboardInterrupt
        return step(self, actions)

    monkeypatch.setattr(StarSwimmerVectorEnv, "step", interrupted)
    out = tmp_path / "out"
    assert studies_main(["rl", *QUICK, "--timesteps", "128", "--out", str(out)]) == 130
    assert "interrupted" in capsys.readouterr().err
    training = pd.read_csv(out / "rl_training.csv")
    assert training["timesteps"].tolist() == [64] and training["episodes"].tolist() == [16]
    assert json.loads((out / "rl_training.csv.json").read_text())["details"]["timesteps"] == 128
    assert PPO.load(out / "rl_policy.zip", device="cpu").num_timesteps == 64
    assert not (out / "rl.csv").exists()


@pytest.mark.slow
def test_a_settled_run_trains_and_drives_to_the_settled_task(tmp_path):
    """--settled: the training's episodes and the drive end only after --settle-cycles periods
    unfired (the sidecar says so); the saved policy driven again with settled=True gives the
    study's table, and an episode's end there is its judgement at rest."""
    from stable_baselines3 import PPO

    out = tmp_path / "out"
    assert studies_main(["rl", *QUICK, "--settled", "--settle-cycles", "3", "--firing-prior",
                         "0.1", "--out", str(out)]) == 0
    details = json.loads((out / "rl.csv.json").read_text())["details"]
    assert details["settled"] is True and details["settle_cycles"] == 3
    assert details["firing_cost_mm"] == 0.1 and details["firing_prior"] == 0.1
    # the observed times since firing reach past the settling: 4 periods of 3.15 s
    assert details["since_fired_cap_s"] == 4 * 3.15
    summary = pd.read_csv(out / "rl.csv")
    model = PPO.load(out / "rl_policy.zip", device="cpu")
    # the policy started firing each actuator with probability 0.1: its action layer's bias
    # logit(0.1), moved since by one epoch of one 64-sample batch, an Adam step of at most
    # the learning rate 3e-4
    np.testing.assert_allclose(model.policy.action_net.bias.detach().numpy(),
                               np.log(0.1 / 0.9), atol=1e-3)
    again, _, _ = drive_policy(lambda obs: model.predict(obs, deterministic=True)[0],
                               summary[["goal_x_mm", "goal_y_mm"]].to_numpy(),
                               taichi_star.StarParams.preset("paper"),
                               taichi_star.SolverConfig(dt=5e-3), max_cycles=2, settle_cycles=3,
                               mode="ppo", settled=True, since_fired_cap_s=4 * 3.15)
    assert again["run_cycles"].tolist() == summary["run_cycles"].tolist()
    np.testing.assert_allclose(again["end_error_mm"], summary["end_error_mm"], rtol=1e-9)
    assert (summary["terminated"] <= summary["reached"]).all()


@pytest.mark.parametrize("argv, message", [
    (["--timesteps", "0"], "--timesteps must be >= 1, got 0"),
    (["--num-envs", "0"], "--num-envs must be in [1, "),
    (["--tolerance", "50"], "--tolerance must be below --distance (50 mm), got 50.0"),
    (["--directions", "0"], "no goals: --directions 0 and --far 0"),
    (["--stop-speed", "0"], "rl: error: --stop-speed: stop_speed_mm_s must be None or a number "
                            "in (0, "),
    (["--firing-cost", "-1"], "rl: error: --firing-cost: firing_cost_mm must be a number in "
                              "[0, 1000], got -1.0"),
    (["--settled", "--settle-cycles", "0"],
     "rl: error: --settle-cycles: settle_cycles must be an integer >= 1 or None, got 0"),
    (["--settled", "--max-episode-steps", "4"],
     "rl: error: --settle-cycles: settle_cycles must be below max_episode_steps (4), got 4"),
    (["--settled", "--max-episode-steps", "1000000", "--settle-cycles", "400000"],
     "rl: error: --settle-cycles: since_fired_cap_s must be a number in (0, 1e+06], got "),
    (["--firing-prior", "0"], "--firing-prior must be in (0, 1), got 0.0"),
    (["--firing-prior", "1"], "--firing-prior must be in (0, 1), got 1.0"),
    (["--firing-prior", "nan"], "--firing-prior must be in (0, 1), got nan"),
    (["--policy", "nowhere.zip"], "--policy nowhere.zip: no such file"),
    (["--policy", POLICY], f"--policy {POLICY}: trained with settled True, this run's "
                           f"--settled gives False"),
    (["--policy", POLICY, "--settled", "--settle-cycles", "3"],
     f"--policy {POLICY}: trained with settle_cycles 4, this run's --settle-cycles gives 3"),
    (["--policy", POLICY, "--settled", "--dt", "0.002"],
     f"--policy {POLICY}: trained at dt 0.005 s, this run at 0.002 s"),
    (["--policy", POLICY, "--settled", "--set", "alpha=0.9"],
     f"--policy {POLICY}: trained on a robot whose alpha is 0.8, this run's 0.9"),
    (["--compare", "nowhere"], "--compare nowhere/plan.csv"),
    (["--directions", "8", "--compare", COMPARED],
     f"--compare {COMPARED}: its goals are not this run's"),
    (["--directions", "7", "--tolerance", "4", "--compare", COMPARED],
     f"--compare {COMPARED}: made with tolerance_mm 5.0, this run's --tolerance 4.0"),
    (["--directions", "7", "--settle-cycles", "3", "--compare", COMPARED],
     f"--compare {COMPARED}: made with settle_cycles 4, this run's --settle-cycles 3"),
    (["--directions", "7", "--dt", "0.002", "--compare", COMPARED],
     f"--compare {COMPARED}: made at dt 0.005 s, this run at 0.002 s"),
    (["--directions", "7", "--set", "alpha=0.9", "--compare", COMPARED],
     f"--compare {COMPARED}: made with a robot whose alpha is 0.8, this run's 0.9"),
])
def test_flags_and_a_plan_run_of_other_settings_are_refused_before_compute(
        no_compute, tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    step = [] if "--dt" in argv else ["--dt", "0.005"]
    assert studies_main(["rl", *step, *argv, "--out", str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert not out.exists()


def test_replot_draws_a_runs_picture_again_from_its_csvs(tmp_path):
    """--replot DIR: rl.png drawn again from the committed run's CSVs (the picture names the
    command), nothing trained or driven; a folder without the run's CSVs refused first."""
    from PIL import Image

    run = tmp_path / "run"
    run.mkdir()
    for name in ("rl_training.csv", "rl_paths.csv", "rl.csv", "rl.csv.json"):
        (run / name).write_bytes((Path("results/rl_settled_longer") / name).read_bytes())
    assert studies_main(["rl", "--replot", str(run)]) == 0
    info = Image.open(run / "rl.png").info
    assert info["study"] == "rl" and info["command"].endswith(f"rl --replot {run}")
    assert sorted(path.name for path in run.iterdir()) == [
        "rl.csv", "rl.csv.json", "rl.png", "rl_paths.csv", "rl_training.csv"]
    (run / "rl_paths.csv").unlink()
    assert studies_main(["rl", "--replot", str(run)]) == 2


def test_a_saved_policy_drives_again_to_its_runs_table(tmp_path):
    """--policy: the committed agent driven again with its run's flags gives that run's rl.csv
    (7 of 7 at rest), nothing trained and no training table or policy written; the sidecar
    names the policy and its SHA-256."""
    import hashlib

    out = tmp_path / "out"
    assert studies_main(["rl", "--dt", "0.005", "--settled", "--policy", POLICY, "--out",
                         str(out), "--no-progress"]) == 0
    pd.testing.assert_frame_equal(pd.read_csv(out / "rl.csv"),
                                  pd.read_csv(Path(POLICY).parent / "rl.csv"))
    assert not (out / "rl_training.csv").exists() and not (out / "rl_policy.zip").exists()
    details = json.loads((out / "rl.csv.json").read_text())["details"]
    assert details["policy_sha256"] == hashlib.sha256(Path(POLICY).read_bytes()).hexdigest()
    assert details["timesteps"] is None and details["ppo"] is None  # nothing trained here
    assert (out / "rl.png").stat().st_size > 1000


@pytest.mark.parametrize("beside, content, message", [
    ((), None, "the record of its run (rl.csv and its sidecar beside it) cannot be read"),
    (("rl.csv", "rl.csv.json"), b"not a zip", "not a saved PPO policy"),
])
def test_a_policy_without_its_runs_record_or_no_policy_is_refused(no_compute, tmp_path, capsys,
                                                                  beside, content, message):
    for name in beside:
        (tmp_path / name).write_bytes((Path(POLICY).parent / name).read_bytes())
    policy = tmp_path / "rl_policy.zip"
    policy.write_bytes(Path(POLICY).read_bytes() if content is None else content)
    out = tmp_path / "out"
    assert studies_main(["rl", "--dt", "0.005", "--settled", "--policy", str(policy), "--out",
                         str(out), "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert f"--policy {policy}: {message}" in error and len(error.strip().splitlines()) == 1
    assert not out.exists()
