"""Refusals of the public API found missing by an audit: each bad argument is a ValueError
naming it (and its range) before any compute; the boundary values on the allowed side pass the
check. No engine is compiled here: `no_compute` makes Taichi's start an error, so a call that
reaches it has accepted its arguments (and one that should have refused them fails)."""

import math
import re
import types
from fractions import Fraction

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star import timegrid
from taichi_star import (CurvatureProfile, experiment, identification, metrics, planner,
                         primitives, profiling, runtime)
from taichi_star.batch import MAX_LOCAL_WORKERS, LocalProcesses, executor_for, run_batch
from taichi_star.gait import Gait
from taichi_star.geometry import build_topology
from taichi_star.params import PER_ACTUATOR_FIELDS, parameter_column
from taichi_star.timegrid import (MAX_STEPS_PER_INSTANCE, check_work, interval_for_count,
                                  nearest_interval)


class ComputeStarted(Exception):
    """Taichi was about to start: every argument check had passed."""


@pytest.fixture
def no_compute(monkeypatch):
    def refuse(*args, **kwargs):
        raise ComputeStarted
    monkeypatch.setattr(runtime.Runtime, "ensure", refuse)


P = ts.StarParams()
S = ts.SolverConfig()
# the most cycles of the paper's 3.15-s period that fit the step counter at dt = 1 ms
MOST_CYCLES = math.floor(MAX_STEPS_PER_INSTANCE * S.dt / P.period * (1 + 1e-12))


# ---------------------------------------------------------------- Simulator.advance
def bare_simulator():
    """A Simulator's argument checks without its engine (none compiled): the steps it has taken
    are 0."""
    sim = ts.Simulator.__new__(ts.Simulator)
    sim.params, sim.solver, sim.arch = (P,), S, "cpu"
    sim.model = types.SimpleNamespace(batch_size=1,
                                      topology=types.SimpleNamespace(n_nodes=P.n_nodes))
    sim._steps = lambda: np.zeros(1, dtype=np.int64)
    return sim


@pytest.mark.parametrize("interval", [None, "", [], False, np.array([0.01, 0.02])])
def test_advance_refuses_a_record_interval_of_another_kind(interval):
    with pytest.raises(ValueError, match=r"^record_interval_s must be a finite number > 0 s"):
        bare_simulator().advance(0.01, record_interval_s=interval)


@pytest.mark.parametrize("flag", ["no", 1, None])
def test_load_refuses_other_params_that_is_not_a_bool(flag):
    # a text "no" was true: the state of other parameters loaded
    with pytest.raises(ValueError, match=r"^other_params must be True or False"):
        bare_simulator().load("missing.npz", other_params=flag)


@pytest.mark.parametrize("interval", [0, 0.0, 0.01, np.float64(0.01)])
def test_advance_accepts_no_records_or_a_positive_interval(interval):
    # accepted: the run's length is refused next
    with pytest.raises(ValueError, match=r"^duration_s = 1e\+09 s"):
        bare_simulator().advance(1e9, record_interval_s=interval)


# ---------------------------------------------------------------- run_batch, executor_for
@pytest.mark.parametrize("keywords, name", [
    ({"resume": "no"}, "resume"), ({"resume": 0}, "resume"), ({"progress": "no"}, "progress"),
    ({"workers": 0}, "workers"), ({"workers": 1.5}, "workers")])
def test_run_batch_refuses_bad_flags_and_workers_before_its_run_folder(tmp_path, no_compute,
                                                                      keywords, name):
    """resume="no" resumed, progress="no" drew bars, and workers=0 was refused only after the
    run folder had been opened (a manifest left that the next call took for an unfinished
    run)."""
    folder = tmp_path / "run"
    with pytest.raises(ValueError, match=f"^{name} must be"):
        run_batch([P], 0.01, run_dir=folder, **keywords)
    assert not folder.exists()


def test_run_batch_accepts_one_worker_and_plain_flags(tmp_path, no_compute):
    folder = tmp_path / "run"
    with pytest.raises(ValueError, match=r"^duration_s = 1e\+09 s"):  # the next check
        run_batch([P], 1e9, run_dir=folder, workers=1, resume=False, progress=np.bool_(False))
    assert not folder.exists()


def test_run_batch_refuses_a_run_dir_that_is_not_a_path(no_compute, tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="^run_dir must be the path of the run store's folder, "
                                         "got int$"):
        run_batch([P], 0.01, run_dir=5)
    # "" was the current folder: refused, nothing written there
    monkeypatch.chdir(tmp_path)
    for empty in ("", "  "):
        with pytest.raises(ValueError, match=re.escape(
                f"run_dir must be the path of the run store's folder, got {empty!r} (the "
                f"current folder is \".\")")):
            run_batch([P], 0.01, run_dir=empty)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("keywords, name", [
    ({"retries": -1}, "retries"), ({"retries": "2"}, "retries"), ({"retries": True}, "retries"),
    # bounded: a chunk that kills its worker at every try was tried again without end
    ({"retries": 101}, "retries"), ({"scheduler": 5}, "scheduler")])
def test_executor_for_refuses_bad_retries_and_schedulers(keywords, name):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        with executor_for(**keywords):
            pass


def test_executor_for_refuses_workers_and_a_scheduler_together():
    # refused before any connection (it would try the scheduler for ~30 s)
    with pytest.raises(ValueError, match=r"^give workers \(local processes\) or scheduler"):
        with executor_for(workers=2, scheduler="tcp://127.0.0.1:9"):
            pass


def test_executor_for_accepts_zero_retries_and_the_most():
    from taichi_star.batch import MAX_RETRIES
    from taichi_star.batch.executors import LocalProcesses

    assert MAX_RETRIES == 100
    for retries in (0, MAX_RETRIES):
        with executor_for(retries=retries) as executor:
            assert executor.n_workers == 1
    assert LocalProcesses(2, retries=MAX_RETRIES).retries == MAX_RETRIES
    with pytest.raises(ValueError, match=r"^retries must be an integer from 0 to 100 "
                                         r"\(MAX_RETRIES\), got 101$"):
        LocalProcesses(2, retries=MAX_RETRIES + 1)


def test_local_processes_are_bounded_before_any_starts():
    """10**6 workers started processes until the memory ran out; the bound itself is allowed
    (no process starts before the first chunk)."""
    with pytest.raises(ValueError, match=r"^workers must be an integer from 1 to 256 "):
        LocalProcesses(MAX_LOCAL_WORKERS + 1)
    with pytest.raises(ValueError, match=r"^workers must be"):
        run_batch([P], 0.01, workers=10**6)
    executor = LocalProcesses(MAX_LOCAL_WORKERS)
    assert executor.n_workers == MAX_LOCAL_WORKERS and executor._pool is None


# ---------------------------------------------------------------- timegrid, check_arch
@pytest.mark.parametrize("steps", [-1.0, -1e-9, "5", None, True])
def test_check_work_refuses_steps_that_are_not_a_count(steps):
    with pytest.raises(ValueError, match=r"^steps must be a real number >= 0"):
        check_work("x", steps)


@pytest.mark.parametrize("batch", [0, -1, 1.5, True, math.nan])
def test_check_work_refuses_a_batch_that_is_not_a_count(batch):
    with pytest.raises(ValueError, match=r"^batch must be an integer >= 1"):
        check_work("x", 5.0, batch)


def test_check_work_accepts_its_boundaries():
    check_work("x", 0.0, 1)
    check_work("x", float(MAX_STEPS_PER_INSTANCE), np.int64(1))
    with pytest.raises(ValueError, match="the limit is"):
        check_work("x", float(MAX_STEPS_PER_INSTANCE + 1), 1)


@pytest.mark.parametrize("count", [0, -1, 1.5, True, "3"])
def test_interval_for_count_refuses_a_count_that_is_not_one(count):
    with pytest.raises(ValueError, match=r"^count must be an integer >= 1"):
        interval_for_count(1.0, count, 1e-3)


@pytest.mark.parametrize("duration", [0.0, -1.0, math.nan, math.inf, "1"])
def test_interval_for_count_refuses_a_duration_that_is_not_one(duration):
    with pytest.raises(ValueError, match=r"^duration_s must be a finite number > 0"):
        interval_for_count(duration, 10, 1e-3)


@pytest.mark.parametrize("dt", [0.0, -1e-3, math.inf, math.nan, "1e-3", True])
def test_interval_for_count_refuses_a_dt_that_is_not_a_step(dt):
    """dt = 0 was a ZeroDivisionError, a negative or infinite one gave a negative or infinite
    interval."""
    with pytest.raises(ValueError, match=r"^dt must be a finite number > 0 s"):
        interval_for_count(1.0, 10, dt)


def test_interval_for_count_refuses_a_duration_of_more_steps_than_a_float_holds():
    with pytest.raises(ValueError, match=r"^duration_s = 1e\+308 s is inf steps of dt = 1e-300 s"):
        interval_for_count(1e308, 1, 1e-300)


def test_interval_for_count_accepts_one_record():
    assert interval_for_count(1.0, 1, 1e-3) == pytest.approx(1.0)


@pytest.mark.parametrize("interval, dt, name", [
    (math.nan, 1e-3, "interval_s"), (math.inf, 1e-3, "interval_s"), (0.0, 1e-3, "interval_s"),
    ("0.01", 1e-3, "interval_s"), (0.01, 0.0, "dt"), (0.01, math.nan, "dt"), (0.01, True, "dt")])
def test_nearest_interval_refuses_what_is_not_a_time(interval, dt, name):
    """NaN was Python's "cannot convert float NaN to integer", dt = 0 a ZeroDivisionError."""
    with pytest.raises(ValueError, match=f"^{name} must be a finite number > 0 s"):
        nearest_interval(interval, dt)


def test_nearest_interval_accepts_less_than_a_step():
    assert nearest_interval(1e-12, np.float64(1e-3)) == 1e-3


def test_an_arch_array_is_refused_naming_arch(no_compute):
    with pytest.raises(ValueError, match=r"^arch must be one of"):
        ts.simulate([P], 0.01, arch=np.array(["cpu", "cuda"]))


# ---------------------------------------------------------------- SimulationResult.animate
def recorded_result(instances=2):
    """A result with recorded shapes (the rest shape twice) built without simulating."""
    topology = build_topology(P)
    row = {column: getattr(P, name) for name, column in ts.StarParams.columns().items()}
    row["actuator_profile"] = P.actuator_profile.to_text()
    for name in PER_ACTUATOR_FIELDS:
        row[parameter_column(name)] = str(getattr(P, name))
    summary = pd.DataFrame([{**row, "status": "ok"}] * instances)
    trajectory = pd.DataFrame({"instance": np.repeat(np.arange(instances), 2),
                               "t_s": np.tile([0.0, 0.1], instances), "x_mm": 0.0, "y_mm": 0.0,
                               "heading_deg": 0.0})
    shapes = np.broadcast_to(topology.rest_positions, (2, instances) + topology.rest_positions.shape)
    return ts.SimulationResult(summary=summary, trajectory=trajectory, shapes=shapes.copy(),
                               topology=topology, solver=S)


@pytest.mark.parametrize("keywords, name", [
    ({"fps": 0}, "fps"), ({"fps": -1}, "fps"), ({"fps": 1001}, "fps"), ({"fps": math.nan}, "fps"),
    ({"fps": 51}, "fps"),  # a GIF's delays are hundredths of a second: 60 fps played at 100
    ({"fps": 1.5}, "fps"), ({"fps": "x"}, "fps"), ({"fps": True}, "fps"),
    ({"size_px": 99}, "size_px"), ({"size_px": 8193}, "size_px"), ({"size_px": 0}, "size_px"),
    ({"size_px": math.nan}, "size_px"),
    ({"instances": [0.5]}, "instances"), ({"instances": [True]}, "instances"),
    ({"instances": 0}, "instances"), ({"instances": ["a"]}, "instances"),
    ({"instances": [math.nan]}, "instances"), ({"instances": np.zeros((1, 1), int)}, "instances"),
    ({"instances": "01"}, "instances"),
    # a 0-d array (a TypeError from list() without the check), a set (no order)
    ({"instances": np.array(1)}, "instances"), ({"instances": {0, 1}}, "instances"),
    ({"frame": "lab"}, "frame")])
def test_animate_refuses_bad_frame_rates_sizes_and_instances(tmp_path, keywords, name):
    pytest.importorskip("matplotlib")
    with pytest.raises(ValueError, match=f"^{name} must be"):
        recorded_result().animate(tmp_path / "movie.gif", **keywords)
    assert not list(tmp_path.iterdir())


def test_animate_refuses_a_gif_over_50_fps_whatever_the_suffixs_case(tmp_path):
    pytest.importorskip("matplotlib")
    with pytest.raises(ValueError, match="^fps must be at most 50 for a GIF"):
        recorded_result().animate(tmp_path / "movie.GIF", fps=51, instances=[2])


def test_animate_refuses_shapes_without_a_topology(tmp_path):
    import dataclasses

    pytest.importorskip("matplotlib")
    with pytest.raises(ValueError, match="^animate needs recorded shapes of one topology"):
        dataclasses.replace(recorded_result(), topology=None).animate(tmp_path / "movie.gif")
    assert not list(tmp_path.iterdir())


def test_animate_draws_the_first_16_instances_by_default(tmp_path, monkeypatch):
    """instances=None: all, up to 16 (one panel each): 16 of a batch of 17, counted before
    anything is drawn."""
    pytest.importorskip("matplotlib")
    from taichi_star import output

    class Drawn(Exception):
        """Stops the call once the instances are chosen."""

    drawn = []

    def hot(times, *args):  # one call per chosen instance
        drawn.append(args)
        return np.zeros((len(times), 8), bool)

    def stop(*args):
        raise Drawn

    monkeypatch.setattr(output.drawing, "periodic_hot_actuators", hot)
    monkeypatch.setattr(output, "_fit_heading", stop)
    with pytest.raises(Drawn):
        recorded_result(17).animate(tmp_path / "movie.gif")
    assert len(drawn) == 16


def test_replay_refuses_a_node_held_twice():
    """Every node of every frame of each gait once: a row repeated is refused (with a missing
    row's check alone the later row won silently)."""
    from taichi_star import output

    result = recorded_result()
    shapes, centroid = output.animation_tables(result, ["a", "b"])
    output.replay(result, shapes, centroid)  # as written: accepted
    doubled = pd.concat([shapes, shapes.iloc[[3]].assign(x_mm=123.0)], ignore_index=True)
    with pytest.raises(ValueError, match="^shapes must hold every node of every frame of each "
                                         "gait once"):
        output.replay(result, doubled, centroid)


@pytest.mark.parametrize("keywords, name", [
    ({"fps": 1}, "movie.gif"), ({"fps": 50}, "movie.gif"), ({"fps": 1000}, "movie.mp4"),
    ({"fps": np.int64(15)}, "movie.gif"), ({"size_px": 100}, "movie.gif"),
    ({"size_px": 8192}, "movie.gif")])
def test_animate_accepts_its_boundaries(tmp_path, keywords, name):
    pytest.importorskip("matplotlib")
    # accepted: the instance out of range is refused next, before anything is drawn
    with pytest.raises(ValueError, match=r"^instances must be in \[0, 2\), got \[2\]"):
        recorded_result().animate(tmp_path / name, instances=[2], **keywords)


# ---------------------------------------------------------------- planner
GOALS = [[50.0, 0.0]]


def model():
    return planner.PrimitiveModel(["A1"], [[10.0, 0.0]], [0.0])


@pytest.mark.parametrize("keywords, name", [
    ({"frames_per_cycle": 0}, "frames_per_cycle"), ({"frames_per_cycle": -1}, "frames_per_cycle"),
    ({"frames_per_cycle": 2.5}, "frames_per_cycle"), ({"frames_per_cycle": True}, "frames_per_cycle"),
    ({"frames_per_cycle": "x"}, "frames_per_cycle"),
    ({"params": None}, "params"), ({"solver": None}, "solver"),
    ({"goals_mm": {}}, "goals_mm"), ({"goals_mm": [["a", "b"]]}, "goals_mm"),
    ({"goals_mm": [[1.0, 2.0], [3.0]]}, "goals_mm")])
def test_check_drive_refuses_bad_arguments(keywords, name):
    arguments = {"goals_mm": GOALS, "params": P, "solver": S, **keywords}
    with pytest.raises(ValueError, match=f"^{name} must be"):
        planner.check_drive(**arguments)


@pytest.mark.parametrize("keywords, name", [
    ({"count": -1}, "count"), ({"count": 2.5}, "count"), ({"count": True}, "count"),
    ({"count": 0, "far_mm": None}, "count"), ({"count": planner.MAX_DEFAULT_GOALS + 1}, "count"),
    ({"count": 10**10}, "count"), ({"distance_mm": math.nan}, "distance_mm"),
    ({"distance_mm": 0.0}, "distance_mm"), ({"far_mm": math.nan}, "far_mm"),
    ({"far_mm": -1.0}, "far_mm")])
def test_default_goals_refuses_bad_counts_and_distances(keywords, name):
    """count 2.5 gave goals at 0°, 144° and 288°, count 0 without far_mm no goal at all,
    10**10 a MemoryError (160 GB), a NaN distance NaN goals."""
    with pytest.raises(ValueError, match=f"^{name} must be"):
        planner.default_goals(**keywords)


def test_default_goals_accepts_no_directions_with_the_far_goal():
    # the plan study's --directions 0 --far 150
    np.testing.assert_array_equal(planner.default_goals(50.0, 0, 150.0), [[-150.0, 0.0]])
    assert planner.default_goals(np.float64(50.0), np.int64(1), None).tolist() == [[50.0, 0.0]]


def test_default_goals_sets_one_goal_per_degree_at_most():
    goals = planner.default_goals(50.0, planner.MAX_DEFAULT_GOALS, None)
    # the bound itself is allowed: 360 goals 1° apart on the 50-mm circle (exact to round-off
    # of cos/sin, 1e-12 mm)
    assert goals.shape == (360, 2)
    np.testing.assert_allclose(np.hypot(*goals.T), 50.0, rtol=1e-12)
    np.testing.assert_allclose(np.degrees(np.arctan2(goals[1, 1], goals[1, 0])), 1.0, rtol=1e-12)


@pytest.mark.parametrize("gaits, match", [
    (["A1", "A1"], r"^gaits must name each gait once, got A1 more"),
    (["A1+A2", "A2+A1"], r"^gaits must name each gait once, got A1\+A2 more"),
    ([], r"^gaits must name at least one gait other than 'none'"),
    (["none"], r"^gaits must name at least one gait other than 'none'")])
def test_primitive_model_refuses_repeated_gaits_or_none(gaits, match):
    """Repeated gaits made a model whose second copy was never chosen; none a model that
    could only stand still."""
    with pytest.raises(ValueError, match=match):
        planner.PrimitiveModel(gaits, np.full((len(gaits), 2), 10.0), np.zeros(len(gaits)))


@pytest.mark.parametrize("call, message", [
    (lambda: planner.PrimitiveModel.from_table("results/primitives.csv"),
     r"^table must be a pandas DataFrame \(pandas.read_csv of a primitives CSV\), got str$"),
    (lambda: planner.PrimitiveModel(["A1"], [["a", "b"]], [0.0]),
     r"^steps_mm must hold numbers \(mm or deg\), got \[\['a', 'b'\]\]$"),
    (lambda: planner.PrimitiveModel(["A1"], [[1.0, 0.0]], [0.0], glides_mm=[["x", 0]]),
     r"^glides_mm must hold numbers"),
    (lambda: planner.PrimitiveModel(None, [[1.0, 0.0]], [0.0]),
     r"^gaits must be a sequence of gait texts, got None$"),
    (lambda: planner.PrimitiveModel("A1", [[1.0, 0.0]], [0.0]),
     r"^gaits must be a sequence of gait texts, got 'A1'$"),
    (lambda: planner.closed_loop_gain(pd.DataFrame()), r"^summary must be drive's summary"),
    (lambda: planner.closed_loop_gain(None), r"^summary must be drive's summary .*NoneType$"),
    (lambda: primitives.measure_glides(fire_cycles=0),
     r"^fire_cycles must be an integer >= 1, got 0$"),
], ids=["table path", "steps text", "glides text", "gaits None", "gaits text", "empty summary",
        "no summary", "fire_cycles"])
def test_planner_and_primitives_name_a_bad_argument(no_compute, call, message):
    """Each was another library's error naming no argument (AttributeError, NumPy's "could not
    convert string to float", KeyError 'mode'), or named `cycles` for fire_cycles (an audit,
    2026-12)."""
    with pytest.raises(ValueError, match=message):
        call()


def test_primitive_model_from_a_table_without_ok_gaits_is_refused():
    table = pd.DataFrame({"gait": ["A1", "A2"], "step_x_mm": [10.0, math.nan],
                          "step_y_mm": [0.0, 0.0], "turn_deg": [0.0, 0.0],
                          "status": ["failed", "ok"]})
    with pytest.raises(ValueError, match=r"^gaits must name at least one gait other"):
        planner.PrimitiveModel.from_table(table)
    assert planner.PrimitiveModel.from_table(table.assign(status="ok")
                                             .iloc[:1]).gaits == ["none", "A1"]


def test_check_drive_accepts_numpy_counts_and_one_frame_per_cycle():
    planner.check_drive(GOALS, P, S, max_cycles=np.int64(3), settle_cycles=np.int64(0),
                        frames_per_cycle=1)


@pytest.mark.parametrize("max_cycles, settle_cycles, refused", [
    (MOST_CYCLES - 4, 4, False), (MOST_CYCLES - 3, 4, True), (MOST_CYCLES, 0, False),
    (1, MOST_CYCLES, True), (10 ** 9, 4, True)])
def test_check_drive_refuses_a_run_past_the_step_counter(max_cycles, settle_cycles, refused):
    """drive(max_cycles=10**9) allocated a (G, 10**9) plan and ran for ever."""
    if refused:
        with pytest.raises(ValueError, match=r"^max_cycles \+ settle_cycles = \d+ cycles of "
                                             r"3.15 s at dt = 0.001 s is .* the limit is"):
            planner.check_drive(GOALS, P, S, max_cycles=max_cycles, settle_cycles=settle_cycles)
    else:
        planner.check_drive(GOALS, P, S, max_cycles=max_cycles, settle_cycles=settle_cycles)


@pytest.mark.parametrize("arguments, keywords, name", [
    ((None, GOALS), {}, "model"), ((model(), GOALS), {"progress": "no"}, "progress"),
    ((model(), GOALS), {"max_cycles": 10 ** 9}, "max_cycles")])
def test_drive_refuses_before_its_simulator(no_compute, arguments, keywords, name):
    with pytest.raises(ValueError, match=f"^{name}"):
        planner.drive(*arguments, **keywords)


def test_drive_starts_with_good_arguments(no_compute):
    with pytest.raises(ComputeStarted):
        planner.drive(model(), GOALS, max_cycles=1, progress=np.bool_(False))


# ---------------------------------------------------------------- primitives
@pytest.mark.parametrize("base, solver, name", [(None, S, "base"), (P, None, "solver"),
                                                ("paper", S, "base")])
def test_check_measurement_refuses_other_objects(base, solver, name):
    with pytest.raises(ValueError, match=f"^{name} must be a"):
        primitives.check_measurement(base, solver, 5, 1)


def test_check_measurement_accepts_numpy_integers():
    primitives.check_measurement(P, S, np.int64(5), np.int64(4))


@pytest.mark.parametrize("glide_cycles, refused", [
    (MOST_CYCLES - 5, False), (MOST_CYCLES - 4, True), (10 ** 9, True)])
def test_measure_glides_refuses_a_run_past_the_step_counter(no_compute, glide_cycles, refused):
    """fire_cycles + glide_cycles periods must fit the step counter: it ran for ever."""
    if refused:
        with pytest.raises(ValueError, match=r"^fire_cycles \+ glide_cycles = \d+ cycles .* "
                                             r"the limit is"):
            primitives.measure_glides(P, S, fire_cycles=5, glide_cycles=glide_cycles)
    else:
        with pytest.raises(ComputeStarted):
            primitives.measure_glides(P, S, fire_cycles=5, glide_cycles=glide_cycles)


def test_measure_primitives_refuses_its_glides_past_the_step_counter(no_compute):
    with pytest.raises(ValueError, match=r"^cycles \+ glide_cycles = \d+ cycles"):
        primitives.measure_primitives(P, S, cycles=5, glide_cycles=MOST_CYCLES - 4)
    with pytest.raises(ComputeStarted):
        primitives.measure_primitives(P, S, cycles=5, glide_cycles=MOST_CYCLES - 5)


@pytest.mark.parametrize("base", [None, "paper", {}])
def test_actuators_equal_refuses_what_is_not_a_star_params(base):
    """None was an AttributeError."""
    with pytest.raises(ValueError, match=r"^base must be a StarParams"):
        primitives.actuators_equal(base)


def test_measure_glides_refuses_a_progress_that_is_not_a_flag(no_compute):
    with pytest.raises(ValueError, match="^progress must be True or False"):
        primitives.measure_glides(P, S, fire_cycles=1, glide_cycles=1, progress="no")


# ---------------------------------------------------------------- identification, experiment
def simulated_run(gait="A1+A2"):
    times = np.arange(0.0, 20.0, 0.1)
    path = identification.CentroidPath(times, times, np.zeros_like(times), 3.15)
    return identification.SimulatedRun(gait, path, (1.0, 0.0))


# -0.5 before the trial's start (its lower bound was untested: a mutation audit); 10**400 past
# a float's range (an OverflowError of math.isfinite, 2026-12)
@pytest.mark.parametrize("phase", ["0", True, -0.5, 10**400])
def test_trial_fit_refuses_a_phase_that_is_not_a_time_in_range(phase):
    trial = identification.measured_trial("A1+A2")
    with pytest.raises(ValueError, match=r"^phase_s must be in \[0, "):
        identification.trial_fit(simulated_run(), trial, phase_s=phase)


def test_trial_fit_accepts_the_ends_of_the_phase_range():
    trial = identification.measured_trial("A1+A2")
    latest = identification.latest_phase(trial, identification.TRAINING_CYCLES)
    for phase in (0.0, latest):
        assert identification.trial_fit(simulated_run(), trial, phase_s=phase).phase_s == phase


@pytest.mark.parametrize("simulated, trial, name", [
    (None, "trial", "simulated"), ("run", None, "trial"), ("run", "run", "trial")])
def test_trial_fit_refuses_other_objects(simulated, trial, name):
    objects = {"run": simulated_run(), "trial": identification.measured_trial("A1+A2"),
               None: None}
    with pytest.raises(ValueError, match=f"^{name} must be a"):
        identification.trial_fit(objects[simulated], objects[trial])


@pytest.mark.parametrize("keywords, match", [
    ({"samples": 10 ** 12}, r"^samples must be an integer in \[1, 1024\]"),
    ({"samples": identification.MAX_SAMPLES_PER_CYCLE + 1}, r"^samples must be an integer in"),
    ({"cycles": (1, 10 ** 12)}, r"^cycles must be integers with 1 <= first <= last <= 1000"),
    ({"cycles": (identification.MAX_CYCLE + 1,) * 2}, r"^cycles must be integers with")])
def test_trial_fit_refuses_windows_past_its_bounds(keywords, match):
    """A window of 10**12 cycles or samples was a MemoryError (terabytes)."""
    trial = identification.measured_trial("A1+A2")
    with pytest.raises(ValueError, match=match):
        identification.trial_fit(simulated_run(), trial, **keywords)


def test_window_and_samples_accept_their_bounds():
    assert identification.check_window((1, identification.MAX_CYCLE)) == (1, 1000)
    grid = identification.tau_grid(3.15, np.int64(identification.MAX_SAMPLES_PER_CYCLE))
    assert len(grid) == 1024 and grid[-1] == 3.15
    with pytest.raises(ValueError, match=r"^samples must be an integer in \[1, 1024\]"):
        identification.tau_grid(3.15, 10 ** 12)
    with pytest.raises(ValueError, match=r"^cycles must be integers with 1 <= first <= last "
                                         r"<= 1000"):
        identification.check_window((1, 10 ** 12))


@pytest.mark.parametrize("gaits", [-1, 0, 2.5, True, "2"])
def test_residual_count_refuses_a_count_of_gaits_that_is_not_one(gaits):
    """-1 gave -193 residuals."""
    with pytest.raises(ValueError, match=r"^gaits must be an integer >= 1"):
        identification.residual_count(gaits)


def test_residual_count_accepts_one_gait_and_the_largest_window():
    assert identification.residual_count(np.int64(1), (1, 3), 16) == 49
    assert identification.residual_count(1, (1, 1000), 1024) == 1000 * 1024 + 1


def test_trajectory_objective_names_a_gait_without_a_phase():
    trials = {"A1+A2": identification.measured_trial("A1+A2")}
    with pytest.raises(ValueError, match=r"^phases has no phase for gait 'A1\+A2'"):
        identification.trajectory_objective({"A1+A2": simulated_run()}, trials, phases={})


@pytest.mark.parametrize("period", [True, 10**400])
def test_a_path_period_of_true_or_past_a_floats_range_is_refused(period):
    with pytest.raises(ValueError, match="^period_s must be a finite number > 0"):
        identification.CentroidPath([0.0, 1.0], [0.0, 1.0], [0.0, 1.0], period)


@pytest.mark.parametrize("t, x", [
    ([0.0, math.nan, 2.0], [0.0, 1.0, 2.0]), ([0.0, 1.0, 2.0], [0.0, math.inf, 2.0]),
    ([[0.0, 1.0], [2.0, 3.0]], [[0.0, 1.0], [2.0, 3.0]])])
def test_cycle_speeds_refuses_non_finite_or_shaped_paths(t, x):
    """A NaN position gave NaN speeds silently; 2-D arrays a TypeError."""
    with pytest.raises(ValueError, match="^cycle_speeds needs finite 1-D t, x, y$"):
        experiment.cycle_speeds(t, x, np.zeros_like(np.asarray(x, dtype=float)), 1.0)


# 10**400: an integer past a float's range, an OverflowError of math.isfinite (an audit, 2026-12)
@pytest.mark.parametrize("period", ["1", True, math.nan, 0.0, -1.0, 10**400])
def test_cycle_speeds_refuses_a_period_that_is_not_a_time(period):
    with pytest.raises(ValueError, match="^period_s must be a finite number > 0 s"):
        experiment.cycle_speeds([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], [0.0, 0.0, 0.0], period)


@pytest.mark.parametrize("period", [1e-9, 5e-324, 2.0 / (experiment.MAX_PATH_CYCLES + 1)])
def test_cycle_speeds_refuses_a_period_of_too_many_cycles(period):
    """1e-9 s cut a 2-s path into 2e9 cycles: a MemoryError."""
    with pytest.raises(ValueError, match=r"^period_s = .* cycles; the limit is 1000000 cycles"):
        experiment.cycle_speeds([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], [0.0, 0.0, 0.0], period)


def test_cycle_speeds_accepts_the_most_cycles_between_samples():
    speeds = experiment.cycle_speeds([0.0, 1.0, 2.0], [0.0, 1.0, 2.0], [0.0, 0.0, 0.0],
                                     2.0 / experiment.MAX_PATH_CYCLES)
    assert len(speeds) == experiment.MAX_PATH_CYCLES
    np.testing.assert_allclose(speeds, 1.0)


@pytest.mark.parametrize("speed", ["x", True, [1.0]])
def test_direction_of_refuses_what_is_not_a_speed(speed):
    with pytest.raises(ValueError, match=r"^signed_speed must be a real number \(mm/s\) or None"):
        experiment.direction_of(speed)


def test_direction_of_reads_numpy_numbers_and_none():
    assert experiment.direction_of(np.float32(-1.0)) == "reverse"
    assert experiment.direction_of(None) == experiment.direction_of(math.nan) == "undefined"


@pytest.mark.parametrize("excerpt", ["no", 0, None])
def test_experimental_speed_refuses_an_excerpt_that_is_not_a_bool(excerpt):
    """excerpt="no" gave the excerpt's speed."""
    with pytest.raises(ValueError, match=r"^excerpt must be True or False"):
        experiment.experimental_speed("A1", excerpt=excerpt)


def test_experimental_speed_accepts_numpy_bools():
    assert experiment.experimental_speed("A1", excerpt=np.bool_(False)) == \
        experiment.experimental_speed("A1")


def test_experimental_cycle_speeds_needs_two_cycles_of_every_trial():
    """Past half the shortest trial a gait had one cycle or none: NumPy's "zero-size array"."""
    durations = {gait: float(np.ptp(experiment.experimental_trajectory(gait)["t_s"]))
                 for gait in experiment.PAPER_GAITS}
    longest = min(durations.values()) / 2
    assert (experiment.experimental_cycle_speeds(longest)["n_cycles"] >= 2).all()
    with pytest.raises(ValueError, match=rf"^period_s must be in \(0, {longest:g}\] s"):
        experiment.experimental_cycle_speeds(longest * (1 + 1e-6))
    for period in ("3", True, math.nan, 10**400):
        with pytest.raises(ValueError, match="^period_s must be a finite number > 0 s"):
            experiment.experimental_cycle_speeds(period)


@pytest.mark.parametrize("summary, match", [
    (None, "^summary must be a simulate"), (pd.DataFrame({"x": [1]}), "^summary has no column 'gait'"),
    (pd.DataFrame({"gait": ["A1"], "speed_mm_s": [1.0]}),
     "^summary has no column 'signed_speed_mm_s'")])
def test_compare_with_experiment_refuses_tables_without_its_columns(summary, match):
    with pytest.raises(ValueError, match=match):
        experiment.compare_with_experiment(summary)


# ---------------------------------------------------------------- profiling
@pytest.mark.parametrize("params, solver, arch, match", [
    ([P], None, "cpu", "^solver must be a SolverConfig"),
    ([P], S, "x", "^arch must be one of"),
    ([ts.StarParams(tip_radius=1.9)], ts.SolverConfig(precision="f32", newton_tol=1e-7), "cpu",
     r"^newton_tol must be >= 3.6e-06 m with precision 'f32'")])
def test_engine_profile_refuses_before_building_the_engine(no_compute, params, solver, arch,
                                                           match):
    with pytest.raises(ValueError, match=match):
        profiling.EngineProfile(params, solver, arch)


def bare_profile(monkeypatch):
    profile = profiling.EngineProfile.__new__(profiling.EngineProfile)
    profile.model = types.SimpleNamespace(batch_size=1)
    profile._engine = types.SimpleNamespace(advance=lambda count: None, n_nodes=P.n_nodes)
    monkeypatch.setattr(profiling.ti, "sync", lambda: None)
    # no engine of the runtime's: its arguments' checks alone
    monkeypatch.setattr(runtime.Runtime, "check_engine_usable", lambda self, engine: None)
    return profile


@pytest.mark.parametrize("steps", [-1, 1.5, True, "10", math.nan, MAX_STEPS_PER_INSTANCE + 1])
def test_engine_profile_advance_refuses_a_step_count_that_is_not_one(monkeypatch, steps):
    with pytest.raises(ValueError, match=r"^n_steps (must be an integer >= 0|= \d+ is)"):
        bare_profile(monkeypatch).advance(steps)


def test_engine_profile_advance_accepts_zero_and_numpy_counts(monkeypatch):
    bare_profile(monkeypatch).advance(0)
    bare_profile(monkeypatch).advance(np.int64(3))


@pytest.mark.parametrize("warmup, steps, name", [(-1, 10, "warmup_steps"), (0, 0, "steps"),
                                                 (0, 2.5, "steps"),
                                                 (MAX_STEPS_PER_INSTANCE, 1, "warmup_steps")])
def test_engine_profile_timed_window_refuses_bad_step_counts(monkeypatch, warmup, steps, name):
    """steps = 0 divided by zero after the run; no count was checked."""
    with pytest.raises(ValueError, match=f"^{name}"):
        bare_profile(monkeypatch).timed_window(warmup, steps)


# ---------------------------------------------------------------- StarParams.from_row, Gait
@pytest.mark.parametrize("row", [None, "gait", 5])
def test_from_row_refuses_what_is_not_a_row(row):
    with pytest.raises(ValueError, match="^row must be a table row"):
        ts.StarParams.from_row(row)


@pytest.mark.parametrize("actuators", [(1.5,), (True,), "12", 5, (math.nan,), ("1",)])
def test_gait_refuses_actuators_that_are_not_whole_numbers(actuators):
    """Gait((1.5,)) was A1, Gait("12") A1+A2."""
    with pytest.raises(ValueError, match=r"^gait actuators must be numbers 1\.\.8"):
        Gait(actuators)


def test_gait_accepts_numpy_actuator_numbers_up_to_eight():
    assert Gait((np.int64(1), 8)).name == "A1+A8"
    with pytest.raises(ValueError, match=r"^gait actuators must be numbers 1\.\.8"):
        Gait((9,))


@pytest.mark.parametrize("mask", [[math.nan] * 8, [2] + [0] * 7, [-1] + [0] * 7,
                                  [0.5] + [0.0] * 7, ["0"] * 8])
def test_an_actuator_mask_must_be_boolean(mask):
    """A NaN (or any nonzero) fired the actuator."""
    with pytest.raises(ValueError, match=r"^an actuator mask must be boolean"):
        Gait.from_mask(mask)


def test_an_actuator_mask_of_booleans_or_bits_is_read():
    assert Gait.from_mask([1, 0, 1, 0, 0, 0, 0, 0]).name == "A1+A3"
    assert Gait.from_mask(np.array([0] * 7 + [1], dtype=np.uint8)).name == "A8"
    assert Gait.from_mask([True] + [False] * 7).name == "A1"


@pytest.mark.parametrize("rotation, reflect, match", [
    ("1", False, r"^rotation must be an integer"), (1.5, False, r"^rotation must be an integer"),
    (True, False, r"^rotation must be an integer"), (None, False, r"^rotation must be an integer"),
    (1, "no", r"^reflect must be True or False"), (1, 0, r"^reflect must be True or False"),
    (1, None, r"^reflect must be True or False")])
def test_gait_transform_refuses_bad_rotations_and_reflections(rotation, reflect, match):
    """A text rotation was a TypeError, 1.5 refused as "gait actuators", reflect="no" true."""
    with pytest.raises(ValueError, match=match):
        Gait.parse("A1+A2").transform(rotation, reflect)


def test_gait_transform_accepts_numpy_integers_and_bools_and_any_turn():
    assert Gait.parse("A2").transform(np.int64(0), np.bool_(True)).name == "A8"
    assert Gait.parse("A1").transform(-1, False) == Gait.parse("A1").transform(7, False)


@pytest.mark.parametrize("period", [0.0, -1.0, math.nan, math.inf, "3", True, 10**400])
def test_cycle_curvature_refuses_a_period_that_is_not_a_time(period):
    """period = 0 gave NaN with the ramp closure; closure_gap alone answered every one of
    these (a gap of 0 for 0 s, NumPy read "3" as 3 s and True as 1 s)."""
    with pytest.raises(ValueError, match=r"^period must be a finite number > 0 s"):
        CurvatureProfile().cycle_curvature(0.0, period, "ramp")
    with pytest.raises(ValueError, match=r"^period must be a finite number > 0 s"):
        CurvatureProfile().closure_gap(period)


def test_cycle_curvature_accepts_a_short_period():
    profile = CurvatureProfile()
    assert profile.cycle_curvature(0.0, np.float64(1e-3), "ramp") == profile.rest_curvature


HUGE = 10 ** 400
"""An integer beyond float's range: an OverflowError or a TypeError naming nothing before
(a review, 2026-12), now refused like any other bad number, naming its argument."""
TINY = Fraction(1, 10 ** 400)
"""A positive number that rounds to 0.0 as the float it is stored as."""


@pytest.mark.parametrize("call, name", [
    (lambda: ts.simulate([P], HUGE), "duration_s"),
    (lambda: ts.simulate([P], TINY), "duration_s"),
    (lambda: ts.simulate([P], 0.01, record_interval_s=HUGE), "record_interval_s"),
    (lambda: run_batch([P], HUGE), "duration_s"),
    (lambda: run_batch([P], cycles=HUGE), "cycles"),
    (lambda: run_batch([P], cycles=TINY), "cycles"),
    (lambda: bare_simulator().advance(HUGE), "duration_s"),
    (lambda: bare_simulator().advance(TINY), "duration_s"),
    (lambda: bare_simulator().advance(0.01, record_interval_s=HUGE), "record_interval_s"),
    (lambda: nearest_interval(HUGE, 1e-3), "interval_s"),
    (lambda: interval_for_count(HUGE, 3, 1e-3), "duration_s"),
    (lambda: ts.SolverConfig(dt=TINY), "dt"),
    (lambda: ts.SolverConfig(dt=np.longdouble("1e-330")), "dt"),
], ids=["simulate huge", "simulate tiny", "records huge", "run_batch huge", "cycles huge",
        "cycles tiny", "advance huge", "advance tiny", "advance records huge",
        "nearest_interval", "interval_for_count", "dt tiny", "dt longdouble"])
def test_numbers_beyond_or_below_floats_reach_are_refused_naming_the_argument(no_compute, call,
                                                                              name):
    with pytest.raises(ValueError, match=f"^{name} must be"):
        call()


def test_cycles_whose_duration_overflows_are_refused_naming_cycles(no_compute):
    """1e306 cycles of 3.15 s are a finite duration but inf steps (an OverflowError had come
    through); 1e308 overflow the duration itself; a count past the step counter from cycles
    names the cycles, not a duration_s the caller never passed."""
    with pytest.raises(ValueError, match=r"^cycles = 1e\+306 \(3\.15e\+306 s for params\[0\]\): "
                                         r"duration_s = .* is inf time steps per instance"):
        run_batch([P], cycles=1e306)
    with pytest.raises(ValueError, match=r"^cycles must give a finite duration: 1e\+308 periods of "
                                         r"params\[0\] \(3\.15 s\) overflow a float$"):
        run_batch([P], cycles=1e308)
    with pytest.raises(ValueError, match=r"^cycles = 1000000000\.0 \(3\.15e\+09 s for "
                                         r"params\[0\]\): duration_s = 3\.15e\+09 s at dt_max"):
        run_batch([P], cycles=1e9, solver=ts.SolverConfig.preset("accurate"))


def test_a_call_no_machine_finishes_in_30_days_is_refused_before_compute(no_compute):
    """100,000 robots for 1e6 s are 1e14 robot-steps: about 322 days at the fastest rate
    measured (an H100's), the bound of a call on a GPU arch; the arch is checked after the
    work, so the refusal comes on a machine without a GPU too. It had started, with only a
    warning."""
    with pytest.raises(ValueError, match=r"^duration_s = 1e\+06 s at dt = 0\.001 s is 1e\+14 "
                                         r"robot-steps: about 322 days even at 3\.6e\+06 "):
        ts.simulate([P] * 100_000, 1e6, arch="gpu")


@pytest.fixture
def two_cores(monkeypatch):
    """This machine seen as 2 cores: the CPU's bound, 2 × 2.5e5 robot-steps/s × 30 days =
    1.296e12 robot-steps, is then the same everywhere."""
    monkeypatch.setattr(timegrid, "usable_cores", lambda: 2)


def refused_by_simulate_and_a_simulator(robot, duration_s: float, shown: str, work: str):
    """1,000 robots like `robot` for duration_s at dt = 1 ms are refused, the message ending in
    `work` (a pattern), by simulate and by a Simulator's advance (`shown`: the duration as the
    message writes it, a pattern)."""
    with pytest.raises(ValueError, match=rf"^duration_s = {shown} s at dt = 0\.001 s " + work):
        ts.simulate([robot] * 1_000, duration_s)
    sim = bare_simulator()
    sim.model.batch_size, sim.model.topology.n_nodes = 1_000, robot.n_nodes
    with pytest.raises(ValueError, match=rf"^duration_s = {shown} s at dt = 0\.001 s \(after "
                                         rf"the 0 steps taken\) " + work):
        sim.advance(duration_s)


def test_a_cpu_call_is_held_to_what_its_cores_finish_in_30_days(no_compute, two_cores):
    """1,000 robots for 2e6 s on the CPU are 2e12 robot-steps, 46 days even at 2.5e5
    robot-steps/s on each of 2 cores (a year and more at the rate measured): refused before
    compute, naming the GPU as a way out. They had started with a warning, held to the
    H100's bound (an audit, 2026-12). On a GPU arch the same call passes the work's check
    (then the arch's, or compute: either means it was not refused for its work)."""
    work = (r"is 2e\+12 robot-steps: about 46\.3 days even at 5e\+05 robot-steps/s \(this "
            r"machine's 2 CPU cores at 2\.5e\+05 each, above the fastest measured per core\) "
            r"and 1\.27 years on a 2-core CPU; the limit is 1\.3e\+12 robot-steps a call \(30 "
            r"days at that rate\): run fewer instances or a shorter duration, on a GPU "
            r"\(arch=\"gpu\"\), or a run_batch spread over several machines$")
    refused_by_simulate_and_a_simulator(P, 2e6, r"2e\+06", work)
    with pytest.warns(timegrid.LongWorkWarning), \
            pytest.raises((ComputeStarted, ValueError), match=r"^(?!duration_s)"):
        ts.simulate([P] * 1_000, 2e6, arch="gpu")


def test_a_fine_meshs_call_is_weighed_by_its_nodes(no_compute, two_cores):
    """n_arc 1000 (8,049 nodes) steps at 41.7 times the work of the paper robot's 193: 1,000
    such robots for 4e4 s (4e10 robot-steps) are 38.6 days even at the 2 cores' bound and are
    refused before compute, by simulate and by a Simulator; the paper robot's same call passes
    the work's check. They were estimated as the paper robot's (an audit, 2026-12)."""
    fine = ts.StarParams(n_arc=1000)
    assert fine.n_nodes == 8049
    work = (r"is 4e\+10 robot-steps of robots of 8,049 nodes \(a step 41\.7 times the work "
            r"of one of the paper robot's 193\): about 38\.6 days even at 1\.2e\+04 "
            r"robot-steps/s \(this machine's 2 CPU cores .*; divided by the work of a step\) "
            r"and 1\.06 years on a 2-core CPU; the limit is 3\.11e\+10 robot-steps a call")
    refused_by_simulate_and_a_simulator(fine, 4e4, "40000", work)
    with pytest.warns(timegrid.LongWorkWarning), \
            pytest.raises((ComputeStarted, ValueError), match=r"^(?!duration_s)"):
        ts.simulate([P] * 1_000, 4e4)


@pytest.mark.parametrize("call, message", [
    (lambda: ts.fewest_steps(None, 1.0, 0.0), "^solver must be a SolverConfig, got NoneType$"),
    (lambda: ts.fewest_steps(S, -1.0, 0.0), "^duration_s must be a finite number >= 0 s"),
    (lambda: ts.fewest_steps(S, math.nan, 0.0), "^duration_s must be a finite number >= 0 s"),
    (lambda: ts.fewest_steps(S, 1.0, -0.1), "^record_interval_s must be a finite number >= 0 s"),
    (lambda: ts.fewest_steps(S, 1.0, math.inf), "^record_interval_s must be a finite number"),
], ids=["solver", "negative", "nan", "records negative", "records inf"])
def test_fewest_steps_refuses_what_is_not_a_run(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_fewest_steps_accepts_its_boundaries():
    assert ts.fewest_steps(S, 0.0, 0.0) == (0.0, "dt = 0.001 s")
    adaptive = ts.SolverConfig.preset("accurate")
    assert ts.fewest_steps(adaptive, 1.0, 0.0)[0] == pytest.approx(1.0 / adaptive.dt_max)


def test_a_step_count_beyond_floats_range_is_too_many_steps():
    with pytest.raises(ValueError, match="is inf time steps per instance; the limit is"):
        check_work("duration_s = 1e400 s", HUGE)


@pytest.mark.parametrize("arguments, message", [
    (dict(duration_s=-1.0), "duration_s must be a finite number > 0 s, got -1.0"),
    (dict(duration_s=0.0), "duration_s must be a finite number > 0 s, got 0.0"),
    (dict(duration_s=0.01, record_interval_s=-0.01),
     "record_interval_s must be a finite number >= 0 s, got -0.01"),
])
def test_simulates_times_are_refused_in_seconds(no_compute, arguments, message):
    """simulate's duration and record interval named their bound without its unit ("> 0.0",
    where the rest of the API says "> 0 s": an audit, 2026-12)."""
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        ts.simulate([P], **arguments)


@pytest.mark.parametrize("call, message", [
    (lambda: timegrid.steps_in(math.nan, 1e-3),
     "^duration_s must be a finite number of s, got nan"),
    (lambda: timegrid.steps_in(1.0, 0.0), "^dt must be a finite number > 0 s, got 0.0"),
    (lambda: timegrid.whole_steps(0.01, 0.0), "^dt must be a finite number > 0 s, got 0.0"),
    (lambda: timegrid.whole_steps(math.inf, 1e-3),
     "^time_s must be a finite number of s, got inf"),
    (lambda: timegrid.steps_in(1e308, 1e-3), r"^duration_s = 1e\+308 s is inf steps of dt "),
    (lambda: timegrid.steps_in(1.0, 5e-324), r"^duration_s = 1.0 s is inf steps of dt = 5e-324"),
], ids=["steps_in nan", "steps_in dt 0", "whole_steps dt 0", "whole_steps inf",
        "steps_in overflow", "steps_in subnormal step"])
def test_the_public_step_helpers_refuse_what_is_not_a_time(call, message):
    """steps_in and whole_steps gave a bare ValueError (NaN), a ZeroDivisionError or None with
    NumPy's warnings (dt = 0) (an audit, 2026-12): ValueErrors naming the argument."""
    with pytest.raises(ValueError, match=message):
        call()


def test_the_public_step_helpers_keep_their_answers_at_their_edges():
    # a time of 0 is no steps; a negative one is a count of steps back (whole_steps' own test)
    assert timegrid.steps_in(0.0, 1e-3) == 0 and timegrid.whole_steps(0.0, 1e-3) == 0
    assert timegrid.whole_steps(-0.002, 1e-3) == -2 and timegrid.whole_steps(0.0015, 1e-3) is None
    # a Python float whatever the argument types (np.int64 count gave np.float64)
    interval = timegrid.interval_for_count(1.0, np.int64(7), 1e-3)
    assert type(interval) is float and interval == 142 * 1e-3


@pytest.mark.parametrize("call, match", [
    # -1 indexed the last boundary and gave a speed of 0
    (lambda: metrics.cycle_window_speeds(ONE_CYCLE, [1.0], ["A1"], -1),
     r"^first_cycle must be a whole number >= 0, got -1$"),
    (lambda: metrics.cycle_window_speeds(ONE_CYCLE, [1.0], ["A1"], 0.5),
     r"^first_cycle must be a whole number >= 0, got 0.5$"),
    # a grid of negative times
    (lambda: identification.tau_grid(-1.0), r"^period_s must be a finite number > 0 s, got -1"),
    (lambda: identification.tau_grid(0.0), r"^period_s must be a finite number > 0 s, got 0"),
    (lambda: identification.tau_grid(math.nan), r"^period_s must be a finite number > 0 s"),
    # 0 GFLOP/s; f16 ran in f32
    (lambda: profiling.matmul_gflops(0, "f64", np.random.default_rng(0)),
     r"^size must be a whole number >= 1, got 0$"),
    (lambda: profiling.matmul_gflops(2.5, "f64", np.random.default_rng(0)),
     r"^size must be a whole number >= 1, got 2.5$"),
    (lambda: profiling.matmul_gflops(4, "f16", np.random.default_rng(0)),
     r"^precision must be one of \['f64', 'f32'\], got 'f16'$"),
    # NumPy's UFuncTypeError, naming no argument
    (lambda: metrics.wrap_degrees("abc"), r"^angle must be real numbers \(deg\), got <U3"),
    # a third component was dropped
    (lambda: metrics.rotate(np.zeros(3), 0.1), r"^vectors must be \(\.\.\., 2\), got shape \(3,\)"),
    (lambda: metrics.rotate(np.float64(1.0), 0.1), r"^vectors must be \(\.\.\., 2\), got shape"),
    # NumPy's broadcast error, or one mass for every node
    (lambda: metrics.centroid(np.zeros((3, 2)), np.ones(4)),
     r"^positions must be \(\.\.\., N, 2\) and mass \(\.\.\., N\), got positions \(3, 2\) and "
     r"mass \(4,\)$"),
    (lambda: metrics.centroid(np.zeros((3, 2)), np.ones(1)), r"^positions must be"),
    (lambda: metrics.centroid(np.zeros((2, 3, 2)), np.ones((3, 3))), r"^positions must be"),
    (lambda: metrics.centroid(np.zeros((3, 3)), np.ones(3)), r"^positions must be"),
])
def test_the_metrics_and_rate_helpers_refuse_what_they_cannot_compute(call, match):
    """Each of these gave a number (a wrong one) or another library's error (an audit,
    2026-12-07)."""
    with pytest.raises(ValueError, match=match):
        call()


ONE_CYCLE = np.array([[[0.0, 0.0], [1e-3, 0.0]]])
"""Centroids (m) at t = 0 and T of one robot that swam 1 mm along +x in its one cycle."""


def test_the_metrics_and_rate_helpers_take_their_bounds():
    """The lowest first_cycle, size, a tiny period, NumPy integers, booleans as angles, a mass
    shared by every shape of a stack."""
    speeds = metrics.cycle_window_speeds(ONE_CYCLE, [2.0], ["A1"], np.int64(0))
    assert speeds["steady_speed_mm_s"].tolist() == [0.5]  # 1 mm over one 2-s cycle
    assert identification.tau_grid(1e-300, 2).tolist() == [5e-301, 1e-300]
    assert profiling.matmul_gflops(np.int64(1), "f32", np.random.default_rng(0)) > 0
    assert metrics.wrap_degrees(np.array([True, 190])).tolist() == [1.0, -170.0]
    shapes = np.array([[[0.0, 0.0], [2.0, 0.0]], [[0.0, 1.0], [0.0, 3.0]]])  # (2, 2, 2)
    mass = np.array([1.0, 3.0])  # the heavier node last
    assert metrics.centroid(shapes, mass).tolist() == [[1.5, 0.0], [0.0, 2.5]]
