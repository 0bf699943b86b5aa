"""The engine's retry and stopping rules at their boundaries, its work counters exact, its
iteration counts pinned (adaptive steps: test_adaptive), f32 refused or flagged where it cannot
resolve the robot, and the public doors of Simulator snapshots: tests that kill the engine
hand-made engine mutants (`halvings <= max` → `<`, an under-counted substep_retries, a changed
Newton stopping rule, a +20 % costlier Newton)."""

import gc
import math
import multiprocessing
import pickle
import signal
import sys
import threading
import warnings

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star import engine as engine_module
from taichi_star import runtime
from taichi_star.profiling import EngineProfile
from taichi_star.reference import ReferenceSimulator
from taichi_star.runtime import Runtime, prepare_engine
from taichi_star.state import STATUS_OK
from taichi_star.stepping import SLIVER_ROUNDINGS


def test_no_substep_halvings_still_takes_every_benign_step():
    """max_substep_halvings = 0 disables the retries, not the step itself: a robot at rest and
    one heating at 1 ms (converging at once) take all their steps."""
    solver = ts.SolverConfig(max_substep_halvings=0)
    summary = ts.simulate([ts.StarParams(gait="none"), ts.StarParams(gait="A1")], 0.01,
                          solver).summary
    assert summary.status.tolist() == ["ok", "ok"]
    assert summary.steps.tolist() == [10, 10]
    assert summary.substep_retries.tolist() == [0, 0]


def _takes_step(engine, saved, halvings) -> bool:
    """Whether the engine takes its next step from `saved` with at most `halvings` halvings
    (the state is left after that attempt)."""
    engine.restore_state(saved)
    engine.max_substep_halvings[None] = halvings
    engine.advance(1)
    return engine.state.status.to_numpy()[0] == STATUS_OK


def test_substep_retries_counts_exactly_the_steps_the_full_step_could_not_take():
    """At h = 20 ms with at most 5 Newton iterations the heating pulse needs substeps (10 ms
    and 3 until Newton stopped only on an update within newton_tol: then all 8 steps failed
    whole and none was rescued by one halving, 2026-12). Before
    each step the state is saved and the step tried with no substeps allowed (it fails exactly
    when the engine has to retry it with substeps) and, if it fails, with one halving; then the
    step is taken from the saved state with 6 halvings. The counter must equal the number of
    steps that failed whole: several, some of them rescued by a single halving (so a counter
    stuck at one, or one that counts only deeper retries, fails)."""
    engine = prepare_engine([ts.StarParams(gait="A1+A2")],
                            ts.SolverConfig(dt=0.02, max_newton=5, max_substep_halvings=6))
    needed = rescued_by_one_halving = 0
    for _ in range(8):
        saved = engine.save_state()
        if not _takes_step(engine, saved, 0):
            needed += 1
            rescued_by_one_halving += _takes_step(engine, saved, 1)
        assert _takes_step(engine, saved, 6)
    assert needed >= 2 and rescued_by_one_halving >= 1
    assert engine.state.substep_retries.to_numpy()[0] == needed
    assert engine.state.steps_done.to_numpy()[0] == 8


HEATING = [ts.StarParams(gait="A1+A3")]


@pytest.fixture(scope="module")
def heating_state():
    """The paper engine's whole state after 100 steps of A1+A3 (t = 0.1 s, inside the heating
    pulse, where Newton's updates are largest)."""
    engine = prepare_engine(HEATING, ts.SolverConfig())
    engine.advance(100)
    return engine.save_state()


def _engine_step(saved, newton_tol):
    """(positions (N, 2) m, Newton iterations) of one engine step from `saved` at newton_tol
    (the cached engine is loaded again: other tests may have loaded other batches into it)."""
    engine = prepare_engine(HEATING, ts.SolverConfig(newton_tol=newton_tol))
    engine.restore_state(saved)
    engine.advance(1)
    iterations = engine.state.newton_total.to_numpy()[0] - saved["newton_total"][0]
    assert engine.state.status.to_numpy()[0] == STATUS_OK
    return engine.state.positions.to_numpy()[0], int(iterations)


@pytest.mark.parametrize("newton_tol", [1e-6, 1e-8, 1e-10])
def test_engine_newton_stops_within_newton_tol_after_the_references_iterations(heating_state,
                                                                               newton_tol):
    """The engine's own stopping rule (an update within newton_tol, max|Δq| ≤ newton_tol): one
    step at newton_tol lands within newton_tol of the same step solved to 1e-14 m, and takes
    exactly the iterations of the NumPy reference's Newton on the same step (same start
    q_k + h(2v_k − v_{k−1}), same rule; the two assemble in another order, a round-off of
    ~1e-16 relative, far from flipping a decision at these tolerances). A looser or stricter
    rule, or a contraction estimate taken again, changes the count."""
    saved = heating_state
    positions, iterations = _engine_step(saved, newton_tol)
    exact, exact_iterations = _engine_step(saved, 1e-14)
    assert np.abs(positions - exact).max() <= newton_tol
    assert iterations < exact_iterations
    reference = ReferenceSimulator(HEATING[0], ts.SolverConfig(newton_tol=newton_tol))
    start = saved["positions"][0], saved["velocities"][0]
    previous = saved["previous"][0], saved["previous_velocities"][0]
    _, _, reference_iterations = reference.step(*start, 0.1, previous=previous)
    assert iterations == reference_iterations


@pytest.mark.parametrize("jacobian, dt, steps", [("newton", 1e-2, 5), ("lagged", 1e-3, 30)])
def test_every_accepted_step_is_within_newton_tol_of_its_solution(jacobian, dt, steps):
    """Each step of three Fig. 4c gaits from rest into their first heating (50 ms at 10-ms
    steps, 30 ms at 1-ms steps), taken at
    newton_tol 1e-10 m, against the same step from the same state solved with Newton's Jacobian
    to 1e-14 m: within newton_tol at every step. The contraction estimate stopped Newton
    12× off at the third 10-ms step of A1+A3 (updates 1.6e-5, 6.3e-5, 7.5e-8 m: θ/(1 − θ)·7.5e-8
    = 8.9e-11, the next update 1.2e-9) and the lagged Jacobian up to 131× off at 1-ms steps
    (an audit, 2026-12)."""
    params = [ts.StarParams(gait=gait) for gait in ("A1+A2", "A1+A3", "A1+A3+A5")]
    taken = ts.Simulator(params, ts.SolverConfig(dt=dt, jacobian=jacobian))
    solved = ts.Simulator(params, ts.SolverConfig(dt=dt, newton_tol=1e-14))
    taken.fire([p.gait for p in params])
    worst = 0.0
    for _ in range(steps):
        start = taken.save()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "stepped with other settings": meant here
            solved.load(start)
        taken.advance(dt)
        solved.advance(dt)
        assert taken.ok.all() and solved.ok.all()
        difference = np.abs(taken.save().fields["positions"] - solved.save().fields["positions"])
        worst = max(worst, difference[:len(params)].max())
    assert worst <= 1e-10, worst


def test_newton_iterations_of_a_fixed_scenario_stay_in_their_band():
    """A regression guard on cost (the adaptive one is in test_adaptive): A1+A3 for 0.4 s
    (heating, then coasting) with the paper solver (fixed 1-ms implicit Euler). Measured at
    this commit (CPU, f64; the same on every run, the engine is deterministic): 400 steps in 875
    Newton iterations, no retry (800 while the contraction estimate stopped solves: the NumPy
    reference makes the same 875). Band ±5 %: room for a change of round-off that moves a few
    decisions, while a regression of +23 % iterations, or the estimate back (−8.6 %), fails."""
    fixed = ts.simulate([ts.StarParams(gait="A1+A3")], 0.4, ts.SolverConfig()).summary.iloc[0]
    assert fixed.steps == 400 and fixed.substep_retries == 0
    assert 0.95 * 875 <= fixed.newton_iterations_mean * fixed.steps <= 1.05 * 875


def test_simulator_load_refuses_what_is_not_a_snapshot_with_a_value_error(tmp_path):
    """Simulator.load of a non-path, a missing file, a file that is not an .npz (a pickle
    numpy would refuse with its own message) or an .npz without the header: ValueError naming
    the argument or the file, the state unchanged."""
    sim = ts.Simulator([ts.StarParams(gait="none")])
    before = sim.save().fields
    pickled = tmp_path / "state.pkl"
    pickled.write_bytes(pickle.dumps({"positions": [1, 2]}))
    foreign = tmp_path / "foreign.npz"
    np.savez(foreign, positions=np.zeros(3))
    cases = [(42, "snapshot must be a SimulatorSnapshot or the path of its .npz file, got int"),
             (tmp_path / "missing.npz", "missing.npz: cannot read it"),
             (pickled, "state.pkl: not a Simulator snapshot"),
             (foreign, "foreign.npz: not a Simulator snapshot")]
    for snapshot, message in cases:
        with pytest.raises(ValueError, match=message):
            sim.load(snapshot)
    after = sim.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)


def test_f32_agrees_with_f64_or_flags_the_iteration_cap():
    """A small robot (joint_radius 12 mm, 3-cm limbs) and a large one (25-cm limbs), in f32 at
    newton_tol 1e-6 m (the floor for 25 cm is 4.8e-7 m) against f64: at h = 1 ms their 0.1-s
    speeds agree within 1 % (measured 0.04 %: f32's envelope, `F32_MAX_SIZE_TO_EDGE`, was
    chosen where f32 stays within 0.7 %). At h = 50 ms f32 cannot solve their steps to 1e-6 m
    (stiff limbs over long steps amplify its rounding): their Newton solves run out of
    iterations, the steps are rescued by substeps, and the results are far off (0.06 → 2.4
    mm/s); they come out "ok" but flagged newton_capped, with a RuntimeWarning, while f64
    solves the same steps without reaching the cap. The file's f32 tests follow it: switching
    Taichi to f32 drops the f64 engines compiled before, once for all of them."""
    batch = [ts.StarParams(gait="A1+A2", joint_radius=0.012, tip_radius=0.03),
             ts.StarParams(gait="A1+A2", tip_radius=0.25)]
    runs = {"fine": (1e-3, 0.1), "coarse": (0.05, 1.0)}
    f64 = {name: ts.simulate(batch, duration, ts.SolverConfig(dt=dt)).summary
           for name, (dt, duration) in runs.items()}
    assert not f64["fine"].newton_capped.any() and not f64["coarse"].newton_capped.any()
    f32 = ts.SolverConfig(precision="f32", newton_tol=1e-6)
    fine = ts.simulate(batch, 0.1, f32.replace(dt=1e-3)).summary
    assert not fine.newton_capped.any()
    np.testing.assert_allclose(fine.speed_mm_s, f64["fine"].speed_mm_s, rtol=0.01)
    with pytest.warns(RuntimeWarning, match=r"2 of 2 f32 instances \(the first: instance 0\) "
                                            r"are 'ok' only after a Newton solve used all its 25 "
                                            r"iterations"):
        coarse = ts.simulate(batch, 1.0, f32.replace(dt=0.05)).summary
    assert (coarse.status == "ok").all() and coarse.newton_capped.all()
    assert (coarse.newton_iterations_max == 25).all() and (coarse.substep_retries > 0).all()


def test_a_precision_switch_is_refused_while_a_simulator_lives_and_allowed_once_let_go():
    """Taichi runs one program per process, and `ti.init` for another precision destroys the
    one a living Simulator's engine lives in: the Simulator then crashed the process (an LLVM
    assertion, exit 134) or went on from another Simulator's state with status ok (an audit,
    2026-12). An f32 run beside a living f64 Simulator is refused before anything is touched,
    and the Simulator goes on bit for bit as if nothing had been asked; once it is let go, the
    f32 run is made."""
    robots = ts.Simulator([ts.StarParams(gait="A1+A3")] * 2)
    alone = ts.Simulator([ts.StarParams(gait="A1+A3")] * 2)
    for simulator in (robots, alone):
        simulator.advance(0.02)
    f32 = ts.SolverConfig(precision="f32", newton_tol=1e-7)
    with pytest.raises(RuntimeError, match=r"^cannot start Taichi for cpu in f32: 2 living "
                                           r"Simulator\(s\) \(or environments\) hold "
                                           r"engines .* \(f64\).* or make this run in f64 or "
                                           r"in another process$"):
        ts.simulate([ts.StarParams()], 0.01, f32)
    for simulator in (robots, alone):
        simulator.advance(0.02)
    pd.testing.assert_frame_equal(robots.state(), alone.state())
    # let go, one of them in a reference cycle that only the collector frees: the runtime
    # collects before it counts (a mutation audit, 2026-12: its gc.collect was untested)
    robots.own_cycle = [robots]
    gc.disable()
    try:
        del robots, alone, simulator  # the loop's name holds the last one too
        with warnings.catch_warnings():
            # the runtime's own restart is not a user's Taichi program (a mutation audit)
            warnings.simplefilter("error")
            assert ts.simulate([ts.StarParams()], 0.01, f32).summary.status.eq("ok").all()
    finally:
        gc.enable()


def test_an_f32_simulator_refuses_a_firing_at_a_step_its_clock_cannot_hold():
    """With fixed steps a pending firing is kept as its step number in the engine's float: f32
    holds every whole number up to 2²⁴ (accepted), not 2²⁴ + 1 (refused, nothing changed).
    dt = 2⁻¹⁰ s makes both times exact binary multiples of the step. After the f32 test above:
    one switch of Taichi's precision."""
    dt = 2.0 ** -10
    sim = ts.Simulator([ts.StarParams()], ts.SolverConfig(dt=dt, precision="f32", newton_tol=1e-6))
    sim.fire(["A1"], at_s=2 ** 24 * dt)
    before = sim.save().fields
    with pytest.raises(ValueError, match=r"at_s = 16384 s is step 16777217, past the steps the "
                                         r"clock's float32 counts exactly \(at most step "
                                         r"16777216\); use precision 'f64'"):
        sim.fire(["A2"], at_s=(2 ** 24 + 1) * dt)
    # an even step past 2^24 is a whole float32, but the step numbers, compared as float32,
    # round there (a firing could come a step early): refused too (it was accepted, an audit)
    with pytest.raises(ValueError, match=r"is step 16777226, past the steps the clock's "
                                         r"float32 counts exactly \(at most step 16777216\)"):
        sim.fire(["A2"], at_s=(2 ** 24 + 10) * dt)
    after = sim.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)
    assert sim.engine.state.schedule.pending_due.to_numpy()[0, 0] == 2 ** 24


@pytest.fixture
def bounded_time():
    """A run that does not end fails the test after 300 s (these cases take a few seconds)
    instead of hanging the suite: SIGALRM's handler raises between two kernel launches."""
    if not hasattr(signal, "SIGALRM"):
        pytest.skip("needs SIGALRM (POSIX)")

    def expired(signum, frame):
        raise TimeoutError("the run did not end within 300 s")

    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(300)
    yield
    signal.alarm(0)
    signal.signal(signal.SIGALRM, previous)


def test_an_f32_adaptive_run_ends_at_a_stop_that_float32_rounds_down(bounded_time):
    """float32(0.35) < 0.35: the f32 time reached the stop as the device holds it, and the host
    compared it with the f64 stop, launching the kernel forever (an audit; `bounded_time` turns
    that into a failure). After the f32 tests above: no further switch of Taichi's
    precision."""
    assert float(np.float32(0.35)) < 0.35
    sim = ts.Simulator([ts.StarParams()], ts.SolverConfig(adaptive=True, precision="f32",
                                                          newton_tol=1e-7))
    sim.fire(["A1"])
    sim.advance(0.35)
    assert sim.time_s[0] == np.float32(0.35) and sim.state().status[0] == "ok"


def test_f32_adaptive_steps_between_close_records_are_solved(bounded_time):
    """64 f32 roundings are 7.6e-6 s: with records every 5e-6 s (allowed: at least dt_min)
    every step landed within them and was crossed by the clock as a sliver, and the robot stood
    still, status ok (an audit). A sliver is at most half of dt_min now: every step is solved
    (f32 steps this short lose much of the velocities to rounding: docs, Precision)."""
    result = ts.simulate([ts.StarParams(gait="A1")], 0.004, ts.SolverConfig(
        adaptive=True, precision="f32", newton_tol=1e-7), record_interval_s=5e-6)
    summary = result.summary
    assert summary.status[0] == "ok" and summary.steps[0] >= 800  # one step per record at least
    assert abs(summary.displacement_x_mm[0]) > 0


@pytest.mark.parametrize("adaptive, failure_time", [(False, 0.05),
                                                    (True, float(np.float32(0.05)))])
def test_an_f32_failure_time_is_its_steps_end_and_its_records_from_then_on_are_nan(
        adaptive, failure_time):
    """In f32 the engine's failure time is the failing step's end rounded to f32 (0.05 s read
    0.05000000074505806), and the record at that step's end compared as before the failure:
    it showed the frozen position, not NaN, where f64 gives NaN (an audit, 2026-12; the
    adaptive path, a review). With fixed steps the failure time is now failure_step × dt in
    float64, 0.05 exactly; with adaptive ones (held at 50 ms) the engine's own, and records
    are compared with it in the state's precision: every record from it on is NaN, shapes
    too; the record before it is finite."""
    solver = ts.SolverConfig(dt=0.05, max_newton=3, max_substep_halvings=1, precision="f32",
                             newton_tol=1e-7, adaptive=adaptive, dt_min=0.05, dt_max=0.05,
                             error_tol=1e-3)
    stiff = ts.StarParams(gait="A1+A2", youngs_modulus=1e10, limb_stiffness_ratio=1e4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the failure's own warning: expected here
        result = ts.simulate([stiff], 0.2, solver, record_interval_s=0.05, record_shapes=True)
    assert result.summary["status"].iloc[0] == "newton_failed"
    assert result.summary["failure_time_s"].iloc[0] == failure_time
    trajectory = result.trajectory
    after = (trajectory["t_s"] >= 0.05).to_numpy()
    assert trajectory["t_s"].tolist()[:2] == [0.0, 0.05]
    assert trajectory.loc[after, ["x_mm", "y_mm"]].isna().all().all()
    assert trajectory.loc[~after, ["x_mm", "y_mm"]].notna().all().all()
    assert np.isnan(result.shapes[after]).all() and np.isfinite(result.shapes[~after]).all()


# the f32 cases of the output's metrics sit here too: beside the other f32 tests, Taichi
# switches precision (and compiles its engines again) once for the file, not once for each
def test_an_f32_runs_trajectory_heading_is_the_summarys_at_the_same_state():
    """The trajectory's heading was computed from the f32 positions, the summary's and the
    Simulator's from them in float64: at the same final state they differed by ~2 % of a
    heading of 7e-5° (an audit, 2026-12). Now the same computation: equal to the bit."""
    # no newton_tol: f32's own default (1e-7 m), as a plain script would leave it
    solver = ts.SolverConfig(dt=2e-3, precision="f32")
    robots = [ts.StarParams(gait=gait, period=0.2) for gait in ("A1+A2", "A3", "A1+A3+A5")]
    result = ts.simulate(robots, 0.5, solver, record_interval_s=0.5)
    last = result.trajectory[result.trajectory["t_s"] == 0.5].sort_values("instance")
    assert (result.summary["heading_deg"].abs() > 1e-5).all()
    np.testing.assert_array_equal(last["heading_deg"].to_numpy(),
                                  result.summary["heading_deg"].to_numpy())


def _in_forked_child(work) -> str:
    """What `work()` came to in a child forked from this process: "ran", or the RuntimeError's
    message. A child still busy after 60 s (a hang's bound, not a timing: a refusal comes
    before any kernel runs) is killed and the test fails."""
    context = multiprocessing.get_context("fork")
    messages = context.Queue()

    def child_work():
        try:
            work()
            messages.put("ran")
        except RuntimeError as error:
            messages.put(str(error))

    child = context.Process(target=child_work)
    child.start()
    child.join(60)
    hung = child.is_alive()
    if hung:
        child.kill()
    assert not hung
    return messages.get(timeout=10)


@pytest.mark.skipif(sys.platform != "linux", reason="fork is the start method in question on Linux")
def test_a_process_forked_after_taichi_started_is_told_to_use_spawn_instead_of_hanging(
        monkeypatch):
    """Taichi's threads do not survive a fork: a child forked after a simulation waited for
    ever in its first kernel (an audit, 2026-12: a multiprocessing Pool after one `simulate`,
    gymnasium's AsyncVectorEnv). It is refused at once, naming the start methods that work:
    a plain call, a Simulator the parent made (it never asks Taichi to start), and a call after
    the parent asked for a re-initialisation (`configure_compiler` forgets the arch; a review,
    2026-12)."""
    robots = ts.Simulator([ts.StarParams()])
    refused = "forked from one in which Taichi had started"
    for work in (lambda: ts.simulate([ts.StarParams()], 0.01), lambda: robots.advance(0.01)):
        message = _in_forked_child(work)
        assert refused in message and "'spawn'" in message
    monkeypatch.setattr(Runtime.current(), "arch", None)  # as configure_compiler leaves it
    assert refused in _in_forked_child(lambda: ts.simulate([ts.StarParams()], 0.01))
    # a runtime that exists but never started Taichi (configured only, e.g. its lanes) leaves
    # a fork free to start it (a mutation audit, 2026-12: the `started` condition was untested)
    monkeypatch.setattr(Runtime, "_current", Runtime())
    assert _in_forked_child(lambda: Runtime.current().check_not_forked()) == "ran"


@pytest.mark.skipif(sys.platform != "linux", reason="fork is the start method in question on Linux")
def test_a_fork_while_another_thread_holds_the_runtime_or_a_file_does_not_hang_the_child(
        tmp_path):
    """A child forked while another thread of its parent held the runtime's lock (a background
    simulation, then a fork-based Pool) waited for ever on it at its first call, never told to
    use spawn (a review, 2026-12); a file's write lock likewise. The child has its own."""
    from taichi_star import provenance

    ts.simulate([ts.StarParams()], 0.01)  # Taichi started in the parent
    path = tmp_path / "table.csv"
    holding, done = threading.Event(), threading.Event()

    def hold():
        with runtime.RUNTIME_LOCK, provenance._write_lock(path):
            holding.set()
            done.wait()
    thread = threading.Thread(target=hold)
    thread.start()
    holding.wait()
    try:
        assert "forked from one in which Taichi had started" in _in_forked_child(
            lambda: ts.simulate([ts.StarParams()], 0.01))
        assert _in_forked_child(lambda: provenance.write_atomic(path, b"a\n")) == "ran"
    finally:
        done.set()
        thread.join()


def _in_threads(works):
    """Each work's return value, the works run from threads started together (a barrier)."""
    start = threading.Barrier(len(works))
    values = [None] * len(works)

    def run(index):
        start.wait()
        values[index] = works[index]()
    threads = [threading.Thread(target=run, args=(index,)) for index in range(len(works))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return values


def test_calls_from_several_threads_take_turns_and_get_the_numbers_of_a_call_alone():
    """Taichi's runtime is one per process: four `simulate` calls from four threads at once
    drew the same free engine, interleaved their kernels and all returned other speeds as
    "ok" (an audit, 2026-12: A1+A2 -7.8 mm/s against 2.0 alone). With `RUNTIME_LOCK` the
    calls take turns: every table, and a Simulator driven from a fifth thread meanwhile, the
    same to the last bit as run one after the other (an engine's bits do not depend on what
    ran before on it: test_determinism). Run alone first, on this thread, beside a second
    Simulator: the two engines (the Simulator's and the calls') are built here, and the threads
    run them (building one elsewhere: the test below)."""
    gaits = ("A1+A2", "A1+A3", "A1+A4", "A1+A3+A5")

    def call(gait):
        return lambda: ts.simulate([ts.StarParams(gait=gait)], 0.1).summary

    def drive():
        robots = ts.Simulator([ts.StarParams(), ts.StarParams(alpha=1.2)])
        for _ in range(4):
            robots.fire(["A1+A2", "A1+A3"])
            robots.advance(0.025)
        return robots.state()
    works = [call(gait) for gait in gaits] + [drive]
    beside = ts.Simulator([ts.StarParams()])
    alone = [work() for work in works]
    del beside
    for one, concurrent in zip(alone, _in_threads(works)):
        pd.testing.assert_frame_equal(concurrent, one, check_exact=True)


def test_an_engine_needed_on_another_thread_restarts_taichi_there_unless_a_simulator_lives(
        monkeypatch):
    """Taichi builds fields only on the thread that started it: a `simulate` of a new
    topology from another thread raised LLVM's "Assertion failure: std::this_thread::get_id()
    == main_thread_id_" and left the process's Taichi broken for every call after (an audit,
    2026-12). Now Taichi is started again on that thread and the call gets the numbers it gets
    on the first; back here, the next new engine does the same. Where a Simulator lives, that
    would destroy its engine: refused, naming the thread, and the Simulator goes on. The
    second restart warns (threads taking turns restart Taichi at every turn, ~2 s each: a
    review, 2026-12), the first not."""
    monkeypatch.setattr(Runtime.current(), "thread_restarts", 0)
    first = ts.simulate([ts.StarParams(gait="A1+A3")], 0.05).summary
    coarse = [ts.StarParams(gait="A1+A3", n_arc=10)]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the first restart: no warning
        (elsewhere,) = _in_threads([lambda: ts.simulate(coarse, 0.05).summary])
    assert Runtime.current().taichi_thread != threading.get_ident()
    # its engine runs here too (not rebuilt); the paper engine was dropped and is built here
    pd.testing.assert_frame_equal(elsewhere, ts.simulate(coarse, 0.05).summary, check_exact=True)
    assert Runtime.current().taichi_thread != threading.get_ident()
    with pytest.warns(RuntimeWarning, match="started again on another thread to build an "
                                            "engine, a second time"):
        again = ts.simulate([ts.StarParams(gait="A1+A3")], 0.05).summary
    pd.testing.assert_frame_equal(again, first, check_exact=True)
    assert Runtime.current().taichi_thread == threading.get_ident()
    robots = ts.Simulator([ts.StarParams()])
    robots.fire(["A1"])
    (refusal,) = _in_threads([lambda: pytest.raises(RuntimeError, ts.simulate,
                                                    [ts.StarParams(n_arc=11)], 0.01)])
    assert "from a thread other than the one that started Taichi" in str(refusal.value)
    robots.advance(0.01)
    assert robots.ok.all()


def _interrupt(*args, **kwargs):
    raise KeyboardInterrupt


def test_a_ctrl_c_while_taichi_starts_leaves_the_next_call_a_fresh_start(monkeypatch):
    """Ctrl-C inside `ti.init` (an f32 call after f64 ones) left the runtime believing in the
    destroyed f64 program: the next f64 call handed out its engines and crashed the process
    (an audit, 2026-12: an LLVM assertion, rc 134). Now that call starts Taichi again and
    gets the same bits as before."""
    before = ts.simulate([ts.StarParams(gait="A1+A2")], 0.05).summary
    monkeypatch.setattr(runtime, "_open_kernel_cache", _interrupt)  # inside ti.init's block
    with pytest.raises(KeyboardInterrupt):
        ts.simulate([ts.StarParams()], 0.01, ts.SolverConfig(precision="f32", newton_tol=1e-6))
    monkeypatch.undo()
    pd.testing.assert_frame_equal(ts.simulate([ts.StarParams(gait="A1+A2")], 0.05).summary,
                                  before, check_exact=True)


def test_an_engine_build_stopped_half_way_leaves_the_next_call_a_fresh_start(monkeypatch):
    """Ctrl-C while a new engine declares its fields left Taichi's field builder unfinished,
    and every later call failed, of any batch ("Field builder ... is not finalized": an
    audit, 2026-12). Now the next call starts Taichi again, with the same bits as before; where
    a Simulator lives (its engine cannot run either) it says so."""
    before = ts.simulate([ts.StarParams(gait="A1+A2")], 0.05).summary
    monkeypatch.setattr(engine_module, "BlockSystem", _interrupt)  # after the field arena
    with pytest.raises(KeyboardInterrupt):
        ts.simulate([ts.StarParams(n_arc=9)], 0.01)
    monkeypatch.undo()
    pd.testing.assert_frame_equal(ts.simulate([ts.StarParams(gait="A1+A2")], 0.05).summary,
                                  before, check_exact=True)
    robots = ts.Simulator([ts.StarParams()])
    monkeypatch.setattr(engine_module, "BlockSystem", _interrupt)
    with pytest.raises(KeyboardInterrupt):
        ts.simulate([ts.StarParams(n_arc=9)], 0.01)
    monkeypatch.undo()
    with pytest.raises(RuntimeError, match="the last engine's build stopped half way, which "
                                           "leaves Taichi unable to run any kernel.*restart "
                                           "the Python process"):
        ts.simulate([ts.StarParams(gait="A1+A2")], 0.05)
    del robots
    pd.testing.assert_frame_equal(ts.simulate([ts.StarParams(gait="A1+A2")], 0.05).summary,
                                  before, check_exact=True)
    # once Taichi has started again the half-way build is history: a later refusal beside a
    # Simulator gives its own reason (it kept this one: a mutation audit, 2026-12)
    living = ts.Simulator([ts.StarParams(gait="A1+A2")])
    with pytest.raises(RuntimeError) as refusal:
        ts.simulate([ts.StarParams()], 0.01, ts.SolverConfig(precision="f32", newton_tol=1e-7))
    assert "stopped half way" not in str(refusal.value)
    assert "or make this run in f64 or in another process" in str(refusal.value)
    living.advance(0.01)  # refused before anything was touched: it goes on
    assert living.ok.all()


def test_an_engine_profile_holds_its_engine_while_it_lives():
    """`EngineProfile` took a free engine and left it free: a `simulate` of the same batch
    meanwhile moved its robots (7.4 mm), a Simulator shared it, an f32 call destroyed it and
    its next step aborted the process (an audit, 2026-12). It holds it now, as a Simulator."""
    params = [ts.StarParams(gait="A1+A2")]
    profile = EngineProfile(params)
    profile.advance(20)
    positions = profile.positions().copy()
    ts.simulate(params, 0.05)
    robots = ts.Simulator(params)
    assert robots.engine is not profile.engine
    np.testing.assert_array_equal(profile.positions(), positions)
    del robots
    with pytest.raises(RuntimeError, match="living Simulator"):
        ts.simulate(params, 0.01, ts.SolverConfig(precision="f32", newton_tol=1e-6))
    np.testing.assert_array_equal(profile.positions(), positions)


def test_f64_instances_ok_only_after_a_solve_used_all_its_iterations_are_warned_about():
    """An f64 instance whose Newton solve used all max_newton iterations is "ok" only because a
    retry rescued the step, and such a run can be off by far more than newton_tol: limbs of
    2e-5 m (tip_radius just past joint_radius, allowed) are retried at every step, and over
    0.05 s their displacement came out 2.2e-8 m from a run at newton_tol 1e-13 against the
    5e-9 m that 50 steps at 1e-10 m allow (an audit, 2026-12; docs/numerics.md, "What ok
    promises"). Warned, naming the first such instance; a batch without one is not."""
    paper = ts.StarParams(gait="A1+A3")
    tiny_limbs = paper.replace(tip_radius=paper.joint_radius + 2e-5)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        plain = ts.simulate([paper], 0.05).summary
    assert not plain.newton_capped.any()
    with pytest.warns(RuntimeWarning, match=r"1 of 2 f64 instances \(the first: instance 1\) "
                                            r"are 'ok' only after a Newton solve used all its 25 "
                                            r"iterations \(newton_capped\): such runs can"):
        summary = ts.simulate([paper, tiny_limbs], 0.05).summary
    assert summary.status.eq("ok").all() and summary.newton_capped.tolist() == [False, True]


def test_a_batchs_capped_instances_are_warned_about_once_with_the_batchs_numbers():
    """run_batch told each chunk's capped instances by the chunk's own rows ("1 of 2 ...
    instance 1" for the batch's fourth), and on worker processes not at all (a review,
    2026-12): one warning from the whole summary, naming the batch's instance."""
    from taichi_star.batch import run_batch

    paper = ts.StarParams(gait="A1+A3")
    tiny_limbs = paper.replace(tip_radius=paper.joint_radius + 2e-5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = run_batch([paper, paper, paper, tiny_limbs], 0.02, chunk_size=2)
    messages = [str(w.message) for w in caught if "newton_capped" in str(w.message)]
    assert len(messages) == 1
    assert messages[0].startswith("1 of 4 f64 instances (the first: instance 3) are 'ok' only")
    assert result.summary.newton_capped.tolist() == [False, False, False, True]


def test_a_warning_a_caller_tells_itself_is_kept_back_in_its_thread_alone():
    """run_batch kept its chunks' "ok"-instance and long-run warnings back with
    warnings.catch_warnings, which swaps the whole process's filters: two threads' batches
    left "ignore" filters installed for good, and a capped run afterwards warned nothing (an
    audit, 2026-12). `told_by_caller` keeps them back in its own thread: another thread's
    warning meanwhile is told, and no filter changes."""
    from taichi_star.checks import told_by_caller
    from taichi_star.simulation import warn_about_capped

    filters = list(warnings.filters)
    inside, told = threading.Barrier(2), threading.Barrier(2)

    def keep_back():
        with told_by_caller("ok_instances"):
            inside.wait()
            told.wait()
    thread = threading.Thread(target=keep_back)
    thread.start()
    inside.wait()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        warn_about_capped(np.array([True]), np.array([0]), ts.SolverConfig())
        with told_by_caller("ok_instances"):
            warn_about_capped(np.array([True]), np.array([0]), ts.SolverConfig())
    told.wait()
    thread.join()
    assert len([w for w in caught if "newton_capped" in str(w.message)]) == 1
    assert warnings.filters == filters


def test_batches_on_two_threads_leave_the_warnings_of_later_calls_alone():
    """The audit's case: two in-process run_batch calls from two threads, then a capped run
    on this one is warned about (and the process's warning filters are as before)."""
    from taichi_star.batch import run_batch

    paper = ts.StarParams(gait="A1+A3")
    tiny_limbs = paper.replace(tip_radius=paper.joint_radius + 2e-5)
    filters = list(warnings.filters)
    with warnings.catch_warnings(record=True):
        warnings.simplefilter("always")
        _in_threads([lambda: run_batch([paper, tiny_limbs], 0.02, chunk_size=1)] * 2)
    assert warnings.filters == filters
    with pytest.warns(RuntimeWarning, match="newton_capped"):
        ts.simulate([tiny_limbs], 0.02)


def test_a_streamed_batchs_capped_instances_are_warned_about_once_with_its_numbers(
        monkeypatch):
    """simulate streams a batch too large for one engine through it in chunks, and each chunk
    warned with its own rows (a review, 2026-12): one warning for the whole batch. Chunks of
    two forced (the batch would need more than an engine's budget otherwise)."""
    from taichi_star import simulation

    monkeypatch.setattr(simulation, "stream_chunk_size", lambda *args: 2)
    paper = ts.StarParams(gait="A1+A3")
    tiny_limbs = paper.replace(tip_radius=paper.joint_radius + 2e-5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ts.simulate([paper, paper, paper, tiny_limbs], 0.02)
    messages = [str(w.message) for w in caught if "newton_capped" in str(w.message)]
    assert messages and messages[0].startswith("1 of 4 f64 instances (the first: instance 3)")
    assert len(messages) == 1


class _Accepted(Exception):
    """Raised by a stand-in model builder: the call passed every check before compute."""


def test_runs_beyond_the_step_counter_are_refused_before_any_compute(monkeypatch):
    """Fixed steps: duration_s / dt steps; adaptive: duration_s / dt_max (the fewest it can
    take). At exactly MAX_STEPS_PER_INSTANCE (2³¹ − 1, the int32 counter) the run is accepted,
    one step more is refused naming the arguments, the estimate and the limit. dt = 2⁻¹⁰ s makes
    the durations exact binary multiples of the step. An adaptive run whose most steps (at
    dt_min) could pass the limit is accepted with a warning (the engine stops an instance
    there: `test_an_adaptive_robot_stops_at_the_step_limit_or_a_step_that_cannot_advance`)."""
    def accepted(*args, **kwargs):
        raise _Accepted
    monkeypatch.setattr("taichi_star.sensitivities.build_model", accepted)
    limit = ts.MAX_STEPS_PER_INSTANCE
    assert limit == np.iinfo(np.int32).max
    dt = 2.0 ** -10
    fixed = ts.SolverConfig(dt=dt)
    with pytest.raises(_Accepted):
        ts.simulate([ts.StarParams()], limit * dt, fixed)
    with pytest.raises(ValueError, match=rf"duration_s = 2.09715e\+06 s at dt = 0.000976562 s is "
                                         rf"2.15e\+09 time steps per instance \(4.29e\+09 "
                                         rf"robot-steps for 2 instances\); the limit is {limit}"):
        ts.simulate([ts.StarParams()] * 2, (limit + 1) * dt, fixed)
    with pytest.raises(ValueError, match=r"duration_s = 1e\+09 s at dt = 0.001 s is 1e\+12 time"):
        ts.simulate([ts.StarParams()], 1e9)
    with pytest.raises(ValueError, match=r"duration_s = 1 s at dt = 1e-300 s is 1e\+300 time"):
        ts.simulate([ts.StarParams()], 1.0, ts.SolverConfig(dt=1e-300))
    adaptive = ts.SolverConfig.preset("accurate", dt_min=dt, dt=dt, dt_max=dt)
    with pytest.raises(_Accepted):
        ts.simulate([ts.StarParams()], limit * dt, adaptive)
    with pytest.raises(ValueError, match=r"at dt_max = 0.000976562 s \(the adaptive lower bound\) "
                                         r"is 2.15e\+09 time steps"):
        ts.simulate([ts.StarParams()], (limit + 1) * dt, adaptive)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(_Accepted):  # at most the limit: no warning
            ts.simulate([ts.StarParams()], limit * dt, adaptive.replace(dt_max=2 * dt))
    with pytest.warns(RuntimeWarning, match=r"at dt_min = 1e-300 s could take 3.15e\+300 steps "
                                            r"per instance: .* stops there with status step_limit"):
        with pytest.raises(_Accepted):
            ts.simulate([ts.StarParams()], 3.15, ts.SolverConfig.preset("accurate", dt_min=1e-300))


@pytest.mark.filterwarnings("ignore:.*could take.*steps per instance:RuntimeWarning")
def test_an_adaptive_robot_stops_at_the_step_limit_or_a_step_that_cannot_advance():
    """With steps of exactly 1 ms (dt_max = dt): a robot whose counter holds 5 steps reaches
    t = 5 ms "ok" on its 5th step and stops at its 6th with status step_limit at 5 ms; with 4,
    at 4 ms. A robot whose next step (1e-30 s) would not move its time at 5 ms stops there
    while its neighbour goes on, bitwise as alone."""
    solver = ts.SolverConfig(integrator="bdf2", adaptive=True, dt=1e-3, dt_min=1e-30,
                             dt_max=1e-3, error_tol=1e-3)
    params = [ts.StarParams(gait="A1", n_arc=6, n_limb=2), ts.StarParams(gait="A2", n_arc=6,
                                                                         n_limb=2)]
    for limit in (5, 4):
        sim = ts.Simulator(params, solver)
        sim.engine.step_limit[None] = limit
        sim.advance(0.005)
        state = sim.state()
        if limit == 5:
            assert (state["status"] == "ok").all() and state["t_s"].tolist() == [0.005] * 2
            sim.advance(0.001)
            state = sim.state()
        assert (state["status"] == "step_limit").all()
        np.testing.assert_allclose(sim.engine.state.failure_time.to_numpy()[:2], limit * 1e-3,
                                   rtol=1e-12)
        assert (sim.engine.state.steps_done.to_numpy()[:2] == limit).all()
        del sim  # its engine goes on to the next Simulator (not a build: the suite's time)
    sim = ts.Simulator(params, solver)
    sim.advance(0.005)
    sizes = sim.engine.state.step_size.to_numpy()
    sizes[0] = 1e-30  # below the rounding of t = 5 ms (~9e-19 s)
    sim.engine.state.step_size.from_numpy(sizes)
    sim.advance(0.002)
    state = sim.state()
    assert state["status"].tolist() == ["step_limit", "ok"]
    assert sim.engine.state.failure_time.to_numpy()[0] == pytest.approx(0.005, rel=1e-12)
    alone = ts.Simulator(params[1:], solver)
    alone.advance(0.007)
    neighbour, by_itself = state.iloc[1].drop("instance"), alone.state().iloc[0].drop("instance")
    pd.testing.assert_series_equal(neighbour, by_itself, check_names=False)


def test_an_ok_instance_with_an_unphysical_shape_is_reported_in_a_warning():
    """Every step solved ("ok") but the rods strained beyond the sanity limit: the run says so
    in a RuntimeWarning naming the count and the first instance (a default robot beside it is
    sane; alone it runs without the warning)."""
    flailing = ts.StarParams(gait="A1+A2+A3+A4+A5+A6+A7+A8", alpha=10, fluid_density=2e4,
                             cylinder_mass_per_height=1e-3, added_mass_coeff=0,
                             actuator_gains=(5.0,) * 8, youngs_modulus=1e3,
                             limb_stiffness_ratio=0.01)
    with pytest.warns(RuntimeWarning, match=r"^1 of 2 'ok' instances \(the first: instance 1\) "
                                            r"end in a shape that is not physical \(shape_sane "
                                            r"False, max_strain up to 0.15\)"):
        result = ts.simulate([ts.StarParams(), flailing], 0.2)
    assert result.summary.status.tolist() == ["ok", "ok"]
    assert result.summary.shape_sane.tolist() == [True, False]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ts.simulate([ts.StarParams()], 0.2)


def _warned_here(call) -> list:
    """The RuntimeWarnings `call()` emits, each asserted to point at this file, where the
    user's line is (not inside the library)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        call()
    runtime_warnings = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert runtime_warnings
    for warning in runtime_warnings:
        assert warning.filename == __file__, (warning.filename, str(warning.message)[:60])
    return runtime_warnings


def test_warnings_point_at_the_users_line_whichever_route_led_to_them(monkeypatch):
    """Fixed stack levels pointed some warnings inside the library (simulation.py, driver.py,
    batch/run.py: an audit, 2026-12), where a user's filter or a notebook's message cannot
    tell which of their lines asked: every route names the caller's file."""
    from taichi_star import timegrid
    from taichi_star.batch import run_batch

    paper = ts.StarParams(gait="A1+A3")
    _warned_here(lambda: ts.simulate([paper], 0.01, record_interval_s=0.02))
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 5)
    _warned_here(lambda: ts.simulate([paper], 0.01))
    robots = ts.Simulator([paper])
    _warned_here(lambda: robots.advance(0.01))
    _warned_here(lambda: run_batch([paper] * 2, 0.01, chunk_size=1))
    monkeypatch.undo()
    _warned_here(lambda: ts.simulate([paper.replace(tip_radius=paper.joint_radius + 2e-5)], 0.01))


@pytest.mark.parametrize("auto_progress_s, shown", [(0.0, True), (math.inf, False)])
def test_the_default_progress_follows_the_estimated_work_on_every_route(monkeypatch, capsys,
                                                                        auto_progress_s, shown):
    """progress=None, the default of simulate, Simulator.advance and run_batch, draws a bar
    (tqdm's, on stderr) exactly where the work is estimated at AUTO_PROGRESS_S or more: with
    the threshold at 0 s every call draws one, at infinity none (a review, 2026-12: a mutant
    that never drew the bar passed every test). The environments never draw one: an agent
    steps them many times a second."""
    from taichi_star import driver
    from taichi_star.batch import run_batch
    from taichi_star.envs import StarSwimmerVectorEnv

    monkeypatch.setattr(driver, "AUTO_PROGRESS_S", auto_progress_s)
    paper = ts.StarParams(gait="A1+A3")
    robots = ts.Simulator([paper])
    envs = StarSwimmerVectorEnv(1, control_period_s=0.01)
    capsys.readouterr()
    envs.reset(seed=0)
    envs.step(np.ones((1, 8), dtype=np.int8))
    assert "robot" not in capsys.readouterr().err
    for call in (lambda: ts.simulate([paper], 0.01), lambda: robots.advance(0.01),
                 lambda: run_batch([paper] * 2, 0.01, chunk_size=1)):
        call()
        assert ("robot" in capsys.readouterr().err) is shown
    envs.close()


def test_a_failed_instances_shape_metrics_are_not_its_frozen_shapes():
    """A failed robot's max_strain is NaN and its shape_sane False, like its other metrics
    (its frozen last good shape gave max_strain 0.0 and shape_sane True, and it passed a
    `summary[summary.shape_sane]` filter: an audit, 2026-12); its running neighbour keeps its
    own, and no warning of an unphysical ok shape counts the failed one."""
    solver = ts.SolverConfig(dt=0.05, max_newton=3, max_substep_halvings=0)
    robots = [ts.StarParams(gait="A1+A2", youngs_modulus=1e10, limb_stiffness_ratio=1e4),
              ts.StarParams(gait="none")]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = ts.simulate(robots, 0.1, solver).summary
    assert summary["status"].tolist() == ["newton_failed", "ok"]
    assert np.isnan(summary["max_strain"].iloc[0]) and not summary["shape_sane"].iloc[0]
    assert summary["max_strain"].iloc[1] == 0.0 and summary["shape_sane"].iloc[1]
    assert not any("not physical" in str(w.message) for w in caught)


@pytest.mark.parametrize("precision, eps", [
    ("f64", np.finfo(np.float64).eps),
    # suite time: an f32 engine compiled cold and Taichi started again for the files after
    # it (~10 s in a cold run); f64's case stays in the default tier
    pytest.param("f32", np.finfo(np.float32).eps, marks=pytest.mark.slow)])
def test_load_sets_the_slivers_bounds_of_the_precision_and_dt_min(precision, eps):
    """`load` gives the kernels 64 roundings of the run's own precision and 1e-4 and 0.5 of
    dt_min as a sliver's bounds (a mutation audit, 2026-12-07: f64's roundings in every
    precision, or the bounds' constants swapped, lived through the suite)."""
    solver = ts.SolverConfig(adaptive=True, precision=precision, dt_min=2e-6,
                             newton_tol=1e-10 if precision == "f64" else 1e-6)
    engine = prepare_engine([ts.StarParams(gait="A1", n_arc=6, n_limb=2)], solver)
    assert engine.sliver_limit[None] == pytest.approx(SLIVER_ROUNDINGS * eps,
                                                      rel=1e-6)
    assert engine.sliver_least[None] == pytest.approx(1e-4 * 2e-6, rel=1e-6)
    assert engine.sliver_most[None] == pytest.approx(0.5 * 2e-6, rel=1e-6)
