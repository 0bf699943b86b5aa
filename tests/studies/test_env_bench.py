"""env_bench's work checked before any environment is built: the robot-steps of every preset
and Jacobian setting together, refused past the library's limit or estimated when long (each
setting's steps were checked alone, and --num-envs 65536 --steps 50000, 1.03e13 robot-steps,
started without a word: an audit, 2026-12). Its quick run is in test_control_studies.py."""


import pytest

from taichi_star import SolverConfig, timegrid

from studies import env_bench
from studies.__main__ import main as studies_main


def no_environments_built(*args, **kwargs):
    raise AssertionError("an environment was built before the run's work was checked")


PAPER_STEPS = 3.15 / SolverConfig.preset("paper").dt
"""Steps of one control period (the actuation period, 3.15 s) at the paper preset's 1 ms."""
ACCURATE_STEPS = 3.15 / SolverConfig.preset("accurate").dt_max
"""The fewest adaptive steps of one: at dt_max (0.05 s), the library's count."""


@pytest.mark.parametrize("argv, rounds, settings, robot_steps", [
    # the audit's run: paper and accurate, 65,536 robots, 50,000 steps and the compiling one,
    # in the default 3 rounds
    (["--num-envs", "65536", "--steps", "50000"], 3, 2,
     65536 * (3 * 50000 + 1) * (PAPER_STEPS + ACCURATE_STEPS)),
    # in one round each setting 6.2e12 robot-steps, under the limit alone, 1.2e13 together
    (["--num-envs", "65536", "--steps", "30000", "--presets", "paper", "--jacobians",
      "newton,chord", "--rounds", "1"], 1, 2, 2 * 65536 * 30001 * PAPER_STEPS),
])
def test_the_robot_steps_of_every_setting_together_are_refused(no_compute, monkeypatch, tmp_path,
                                                               capsys, argv, rounds, settings,
                                                               robot_steps):
    monkeypatch.setattr(env_bench, "measure", no_environments_built)
    out = tmp_path / "out"
    assert studies_main(["env_bench", *argv, "--out", str(out)]) == 2
    error = capsys.readouterr().err
    # the accurate preset's robots (433 nodes) weigh more than the paper's (193) a step
    mesh = " of robots of 198 nodes on average (a step 1.02 times" if rounds == 3 else ":"
    assert (f"error: --num-envs 65536 × --rounds {rounds} × --steps {argv[3]} (+1 compiling) × "
            f"{settings} preset and Jacobian setting(s) is {robot_steps:.3g} robot-steps"
            f"{mesh}") in error and " days even at " in error, error
    assert robot_steps > timegrid.REFUSE_ROBOT_STEPS and len(error.splitlines()) == 1
    assert not out.exists()


QUICK_RUN = ("--num-envs 4 × --rounds 1 × --steps 1 (+1 compiling) × 2 preset and Jacobian "
             "setting(s)")


@pytest.mark.parametrize("limit, value, refused, told", [
    ("REFUSE_ROBOT_STEPS", 639, True, False), ("REFUSE_ROBOT_STEPS", 640, False, False),
    ("WARN_ROBOT_STEPS", 639, False, True), ("WARN_ROBOT_STEPS", 640, False, False)])
def test_the_settings_robot_steps_are_added_up(no_compute, monkeypatch, tmp_path, checked_run,
                                                limit, value, refused, told):
    """--quick's 4 robots, one timed and one compiling step of 0.2 s at 5 ms, with two Jacobian
    settings: 2 × 4 × 2 × 40 = 640 robot-steps, each setting's 320; refused or told past a limit
    of 639, not at 640 (the rule is "over"), before any environment is built."""
    stub, run = checked_run
    monkeypatch.setattr(timegrid, limit, value)
    monkeypatch.setattr(env_bench, "measure", stub)
    error, said = run(["env_bench", "--quick", "--presets", "paper", "--jacobians",
                       "newton,chord", "--out", str(tmp_path / "out")], refused)
    assert (f"error: {QUICK_RUN} is 640 robot-steps: about " in error) == refused
    assert said == ([f"{QUICK_RUN} is 640 robot-steps: about {640 / 5e4 / 3600:.3g} h at 50000 "
                     f"robot-steps/s (on a 2-core CPU; a GPU or more cores run faster)"]
                    if told else [])
