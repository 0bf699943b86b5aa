"""The control studies in --quick mode: primitives (255 gaits, the library's measurement,
a plot, provenance), plan (with the primitives given), env_bench; their argument errors on
one line with exit code 2 before any compute."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import profiling
from taichi_star.lookahead import lookahead_drive
from taichi_star.planner import path_frames
from taichi_star.primitives import glide_columns, measure_primitives, streak_step_columns

from studies import cli
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]


@pytest.fixture(scope="module")
def primitives_run(tmp_path_factory):
    """`python -m studies primitives --quick`: 2 cycles of the 29 classes at dt = 5 ms."""
    out = tmp_path_factory.mktemp("primitives")
    assert studies_main(["primitives", *QUICK, "--out", str(out)]) == 0
    return out


@pytest.mark.slow
def test_primitives_quick_writes_the_measurement_a_plot_and_provenance(primitives_run):
    table = pd.read_csv(primitives_run / "primitives.csv")
    assert len(table) == 255 and (table["status"] == "ok").all()
    assert table["dt_s"].eq(5e-3).all() and table["cycles"].eq(2).all()
    assert table["first_cycle"].eq(1).all()
    cycles = pd.read_csv(primitives_run / "primitives_cycles.csv")
    assert set(cycles["gait"]) == set(table["gait"])
    assert (primitives_run / "primitives.png").stat().st_size > 1000
    for name in ("primitives.csv", "primitives_cycles.csv"):
        sidecar = json.loads((primitives_run / f"{name}.json").read_text())
        assert sidecar["study"] == "primitives" and sidecar["model"]["preset"] == "paper"
        assert sidecar["solver"]["dt"] == 5e-3
        assert sidecar["details"] == {"cycles": 2, "first_cycle": 1, "glide_cycles": 1}


@pytest.mark.slow
def test_primitives_quick_glides_follow_the_symmetries(primitives_run):
    """The glides after 1 and 2 firings in a row (one cycle of coasting under --quick): an
    image gait glides as its class representative turned by the symmetry, a symmetric gait not
    at all, and a swimming gait glides on in the direction it swam; the per-streak steps are
    the per-cycle table's."""
    table = pd.read_csv(primitives_run / "primitives.csv").set_index("gait")
    assert (table["glide_cycles"] == 1).all()
    assert not set(glide_columns(3)) & set(table.columns)  # --quick: 2 cycles
    for fired in (1, 2):
        x, y = glide_columns(fired)
        length = np.hypot(table[x], table[y])
        # A1+A3 and its rotation by one actuator, A2+A4: same glide length, turned by 45°. The
        # image's glide is the representative's turned, then both rounded to the CSV's 10
        # digits: each length within 5e-10 (relative), each direction within 5e-10 rad, so
        # the lengths agree to 1e-9 at worst (2e-9 asked; 7e-11 measured) and the turn to
        # 1e-9 rad = 6e-8° (1e-7° asked; 5e-11° measured). The symmetric gait's glide is
        # round-off: 1e-12 of A1+A3's measured, 1e-6 asked
        assert length["A2+A4"] == pytest.approx(length["A1+A3"], rel=2e-9)
        turn = np.degrees(np.arctan2(table.loc["A2+A4", y], table.loc["A2+A4", x])
                          - np.arctan2(table.loc["A1+A3", y], table.loc["A1+A3", x]))
        assert (turn - 45.0 + 180.0) % 360.0 - 180.0 == pytest.approx(0.0, abs=1e-7)
        assert length["A1+A5"] < 1e-6 * length["A1+A3"]
        moving = table[table["step_mm"] > 0.5]
        assert (moving[x] * moving["step_x_mm"] + moving[y] * moving["step_y_mm"] > 0).all()
    cycles = pd.read_csv(primitives_run / "primitives_cycles.csv")
    second = cycles[cycles["cycle"] == 1].set_index("gait")
    x, y = streak_step_columns(2)
    np.testing.assert_array_equal(table.loc[second.index, x], second["dx_body_mm"])
    np.testing.assert_array_equal(table.loc[second.index, y], second["dy_body_mm"])


@pytest.mark.slow
def test_primitives_quick_equals_the_library_measurement(primitives_run):
    """The CSV is `measure_primitives` of the same robot and step (the library's own tests
    check the measurement)."""
    table = pd.read_csv(primitives_run / "primitives.csv")
    row = table[table["gait"] == "A1+A3"]
    direct, _ = measure_primitives(taichi_star.StarParams(gait="A1+A3"),
                                   taichi_star.SolverConfig(dt=5e-3), cycles=2, first_cycle=1)
    expected = direct[direct["gait"] == "A1+A3"]
    # the CSV keeps 10 significant digits of the same bits (a result does not depend on its
    # batch): exactly the direct measurement's
    for column in ("step_x_mm", "step_y_mm", "turn_deg"):
        assert row[column].iloc[0] == float(f"{expected[column].iloc[0]:.10g}"), column


@pytest.mark.slow
def test_plan_quick_with_given_primitives(primitives_run, tmp_path):
    primitives = str(primitives_run / "primitives.csv")
    code = studies_main(["plan", *QUICK, "--primitives", primitives, "--directions", "2",
                         "--far", "0", "--out", str(tmp_path)])
    assert code == 0
    summary = pd.read_csv(tmp_path / "plan.csv")
    assert len(summary) == 4 and (tmp_path / "plan.png").stat().st_size > 1000
    # a goal is judged at rest, after the settling cycle
    assert (summary["reached"] == (summary["end_error_mm"] <= 5.0)).all()
    cycles = pd.read_csv(tmp_path / "plan_cycles.csv")
    assert (summary["run_cycles"] == cycles["cycle"].max() + 1).all()
    assert not (tmp_path / "primitives.csv").exists()  # given, not measured
    gain = pd.read_csv(tmp_path / "plan_gain.csv")
    assert {"open_mean_error_mm", "closed_mean_error_mm"} <= set(gain.columns)
    for name in ("plan.csv", "plan_gain.csv", "plan_cycles.csv", "plan_paths.csv"):
        sidecar = json.loads((tmp_path / f"{name}.json").read_text())
        # the table given, by its whole path and content (a relative path was all, an audit)
        assert sidecar["details"]["primitives"] == str(Path(primitives).resolve())
        assert sidecar["details"]["primitives_sha256"] == hashlib.sha256(
            Path(primitives).read_bytes()).hexdigest() and sidecar["study"] == "plan"


def lookahead_plan(primitives_run, out, *extra):
    """`plan --quick --lookahead` on two goals into `out`: its exit code."""
    return studies_main(["plan", *QUICK, "--primitives", str(primitives_run / "primitives.csv"),
                         "--directions", "2", "--far", "0", "--lookahead", "--out", str(out),
                         *extra])


@pytest.fixture(scope="module")
def lookahead_run(primitives_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("lookahead")
    assert lookahead_plan(primitives_run, out) == 0
    return out


@pytest.mark.slow
def test_plan_with_the_lookahead_drives_the_same_goals_and_compares_the_controllers(
        lookahead_run):
    tmp_path = lookahead_run
    assert not (tmp_path / "resume").exists()  # the checkpoint is gone with its tables written
    plan = pd.read_csv(tmp_path / "plan.csv")
    ahead = pd.read_csv(tmp_path / "lookahead.csv")
    assert ahead["mode"].tolist() == ["lookahead"] * 2
    assert ahead[["goal_x_mm", "goal_y_mm"]].equals(
        plan[plan["mode"] == "closed"][["goal_x_mm", "goal_y_mm"]].reset_index(drop=True))
    # the library's own run on the same goals: the same table to the CSV's digits
    direct, _, _ = lookahead_drive(ahead[["goal_x_mm", "goal_y_mm"]].to_numpy(),
                                   taichi_star.StarParams.preset("paper"),
                                   taichi_star.SolverConfig(dt=5e-3), max_cycles=2,
                                   settle_cycles=1, gaits=[f"A{m}" for m in range(1, 9)],
                                   frames_per_cycle=10)
    np.testing.assert_allclose(ahead["end_error_mm"], direct["end_error_mm"], rtol=1e-9)
    controllers = pd.read_csv(tmp_path / "controllers.csv")
    assert controllers["mode"].tolist() == ["open", "closed", "lookahead"]
    assert controllers["reached"].tolist() == [int(plan[plan["mode"] == mode]["reached"].sum())
                                               for mode in ("open", "closed")] \
        + [int(ahead["reached"].sum())]
    paths = pd.read_csv(tmp_path / "lookahead_paths.csv")
    assert set(paths["goal"]) == {0, 1} and (tmp_path / "plan.png").stat().st_size > 1000
    sidecar = json.loads((tmp_path / "lookahead.csv.json").read_text())
    assert sidecar["details"]["lookahead_gaits"] == [f"A{m}" for m in range(1, 9)]


@pytest.mark.slow
def test_plan_killed_in_the_lookahead_is_continued_by_resume_to_the_same_tables(
        primitives_run, lookahead_run, tmp_path, monkeypatch, capsys):
    import taichi_star.lookahead as lookahead_module
    write = lookahead_module._write_checkpoint

    def write_then_stop(*args, **kwargs):  # a kill right after the first decision is kept
        write(*args, **kwargs)
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(lookahead_module, "_write_checkpoint", write_then_stop)
        assert lookahead_plan(primitives_run, tmp_path) == 130
    error = capsys.readouterr().err
    assert f"the finished work in {tmp_path / 'resume'} is kept: the same command with " \
           f"--resume continues the run" in error, error
    assert not (tmp_path / "lookahead.csv").exists()
    # without --resume the checkpoint is not written over
    assert lookahead_plan(primitives_run, tmp_path) == 2
    assert "holds an unfinished lookahead" in capsys.readouterr().err
    continued_from = []

    def write_noting(path, definition, next_cycle, *args):
        continued_from.append(next_cycle)
        write(path, definition, next_cycle, *args)

    with monkeypatch.context() as patch:
        patch.setattr(lookahead_module, "_write_checkpoint", write_noting)
        assert lookahead_plan(primitives_run, tmp_path, "--resume") == 0
    assert continued_from[0] == 2  # from the first decision's checkpoint on
    for name in ("lookahead.csv", "lookahead_cycles.csv", "lookahead_paths.csv",
                 "controllers.csv", "plan.csv"):
        assert (tmp_path / name).read_bytes() == (lookahead_run / name).read_bytes(), name
    assert not (tmp_path / "resume").exists()


@pytest.mark.slow
def test_plan_refuses_primitives_of_another_robot(primitives_run, tmp_path, capsys):
    """The paper robot's table drove the identified one without a word, reaching 0 of 9
    goals (an audit): the table's sidecar records its robot, and another is refused."""
    out = tmp_path / "out"
    code = studies_main(["plan", *QUICK, "--primitives", str(primitives_run / "primitives.csv"),
                         "--set", "alpha=1.2", "--out", str(out)])
    assert code == 2
    error = capsys.readouterr().err
    assert "measured on a robot whose alpha is 0.8, this run's 1.2 (1 field(s) differ" in error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


def test_env_bench_quick_into_a_fresh_run_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert studies_main(["env_bench", *QUICK, "--presets", "paper"]) == 0
    (folder,) = (tmp_path / "runs" / "env_bench").iterdir()  # runs/env_bench/<timestamp>/
    table = pd.read_csv(folder / "env_bench.csv")
    assert list(table["preset"]) == ["paper"] and (table["robot_seconds_per_s"] > 0).all()
    assert table["num_envs"].tolist() == [4] and table["dt_s"].tolist() == [5e-3]
    assert table["n_nodes"].tolist() == [193]  # the paper robot's (Simulator.n_nodes)
    assert (folder / "env_bench.csv.json").exists()


@pytest.fixture
def no_compute(monkeypatch):
    """Any simulation fails the test: argument errors must come before compute."""
    def forbidden(*args, **kwargs):
        raise AssertionError("a simulation started despite invalid arguments")
    monkeypatch.setattr("taichi_star.primitives.simulate", forbidden)
    monkeypatch.setattr("taichi_star.planner.Simulator", forbidden)
    monkeypatch.setattr("taichi_star.envs.swimmer.Simulator", forbidden)


@pytest.mark.parametrize("argv, message", [
    (["plan", "--tolerance", "-1"], "--tolerance must be > 0"),
    (["plan", "--primitives", "missing.csv"], "--primitives missing.csv"),
    (["plan", "--max-cycles", "0"], "--max-cycles must be >= 1"),
    (["plan", "--directions", "0", "--far", "0"], "no goals"),
    (["plan", "--set", "gait=A1"], "--set gait: set by the plan study"),
    (["plan", "--set", "period=3.1234"], "--dt, --set period"),  # off the step grid
    (["primitives", "--first-cycle", "5"], "--first-cycle must be in [0, --cycles - 1 = 1]"),
    (["primitives", "--cycles", "0"], "--cycles must be > 0"),
    (["primitives", "--set", "period=3.1234"], "--dt, --set period"),
    (["env_bench", "--presets", "fast"], "--presets: unknown value 'fast'"),
    (["env_bench", "--jacobians", "broyden"], "--jacobians: unknown value 'broyden'"),
    (["env_bench", "--num-envs", "0"], "--num-envs must be in [1, "),
    (["env_bench", "--control-period", "0.0123"], "--control-period"),
])
def test_invalid_arguments_fail_before_compute(no_compute, tmp_path, capsys, argv, message):
    out = tmp_path / "out"
    assert studies_main([*argv, "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert not out.exists()  # nothing written


@pytest.mark.parametrize("study", ["primitives", "plan", "env_bench"])
def test_quick_never_writes_into_the_committed_results(no_compute, capsys, study):
    assert studies_main([study, "--out", str(cli.COMMITTED_RESULTS), *QUICK]) == 2
    assert "never write into the committed results/" in capsys.readouterr().err


@pytest.mark.parametrize("period, dt, frames", [(3.15, 1e-3, 10), (3.15, 2e-3, 9),
                                                (3.15, 5e-3, 10), (3.0, 7e-3, 10)])
def test_the_paths_are_recorded_as_often_as_whole_steps_allow(period, dt, frames):
    """At 2 ms a 3.15-s cycle is 1,575 steps, not a multiple of 10: the study was refused,
    naming the library's frames_per_cycle (an audit, 2026-12); it records 9 frames a cycle
    there, 10 where they divide the cycle, and leaves a period off the step grid (3 s at 7 ms)
    to the library's refusal, which names the period."""
    assert path_frames(period, dt) == frames


class StandInSpace:
    def seed(self, seed):
        pass

    def sample(self):
        return None


class StandInEnvs:
    """env_bench's vector environment stood in for: control periods of 0.5 s, 7 nodes, and
    each step moves `clock` (a one-item list) by the next of `step_seconds[preset]` (the
    first: the untimed one), noting (preset, its number) in `order`."""

    control_period_s = 0.5
    action_space = StandInSpace()
    simulator = type("Sim", (), {"n_nodes": 7})()
    clock, order = [0.0], []
    step_seconds = {"paper": [0.0] * 8, "accurate": [0.0] * 8}

    def __init__(self, num_envs, params, **kwargs):
        self.preset = "paper" if params == taichi_star.StarParams.preset("paper") \
            else "accurate"
        self.steps = 0

    def reset(self, seed):
        pass

    def step(self, action):
        self.clock[0] += self.step_seconds[self.preset][self.steps]
        self.order.append((self.preset, self.steps))
        self.steps += 1


def test_env_bench_counts_robot_steps_only_of_fixed_steps(monkeypatch):
    """robot_steps_per_s counts steps of dt: with adaptive steps (the accurate preset's) that
    counted 1-ms steps the robots did not take, about 11 times too many (an audit, 2026-12):
    NaN there; with fixed steps robot-seconds / dt / wall."""
    from studies import env_bench

    monkeypatch.setattr(env_bench, "StarSwimmerVectorEnv", StandInEnvs)
    adaptive = taichi_star.SolverConfig.preset("accurate")
    assert adaptive.adaptive
    fixed = taichi_star.SolverConfig(dt=5e-3)
    adaptive_row, fixed_row = env_bench.measure([("accurate", adaptive), ("paper", fixed)],
                                                num_envs=4, steps=3)
    assert np.isnan(adaptive_row["robot_steps_per_s"])
    assert adaptive_row["robot_seconds_per_s"] > 0
    assert fixed_row["robot_steps_per_s"] == pytest.approx(4 * 3 * 0.5 / 5e-3
                                                           / fixed_row["wall_s"])


def test_env_bench_times_its_settings_in_interleaved_rounds(monkeypatch):
    """Each setting was timed once, one after the other (an audit, 2026-12): now every setting
    is built and stepped once untimed, then each round steps every setting --steps times in
    turn; a row's wall_s is its best round's, wall_s_median the median, and its rates are of
    those. The stand-in environments' steps take set times (a clock moved by each step)."""
    from studies import env_bench

    clock, order = [0.0], []
    monkeypatch.setattr(StandInEnvs, "clock", clock)
    monkeypatch.setattr(StandInEnvs, "order", order)
    monkeypatch.setattr(StandInEnvs, "step_seconds", {"paper": [0.0, 2.0, 3.0, 1.0],
                                                      "accurate": [0.0, 5.0, 4.0, 6.0]})
    monkeypatch.setattr(env_bench, "StarSwimmerVectorEnv", StandInEnvs)
    monkeypatch.setattr(profiling.time, "perf_counter", lambda: clock[0])
    paper, accurate = env_bench.measure(
        [("paper", taichi_star.SolverConfig(dt=5e-3)),
         ("accurate", taichi_star.SolverConfig.preset("accurate"))],
        num_envs=4, steps=1, rounds=3)
    assert order == [("paper", 0), ("accurate", 0), ("paper", 1), ("accurate", 1),
                     ("paper", 2), ("accurate", 2), ("paper", 3), ("accurate", 3)]
    assert (paper["wall_s"], paper["wall_s_median"], paper["wall_s_rounds"]) == (1.0, 2.0,
                                                                                "2;3;1")
    assert (accurate["wall_s"], accurate["wall_s_median"]) == (4.0, 5.0)
    assert paper["robot_seconds_per_s"] == 4 * 0.5 / 1.0
    assert paper["robot_seconds_per_s_median"] == 4 * 0.5 / 2.0
    assert paper["robot_steps_per_s"] == 4 * 0.5 / 5e-3 / 1.0 and paper["rounds"] == 3
