"""EngineProfile's bookkeeping with a fake engine and a fake clock: the timed window's restart
and counts per instance-step, its refusal of a failed instance, the launches of `advance`, the
first launch's compile time, the phase split's arithmetic and repetitions, and the bytes a
Newton iteration moves. No Taichi, no real timing. Found by a mutation audit (2026-12-07): each
test kills a change of the code that the suite let live."""

from types import SimpleNamespace

import numpy as np
import pytest

import taichi_star as ts
from taichi_star import profiling, runtime as runtime_module


class _Array:
    def __init__(self, values):
        self.values = np.array(values)

    def to_numpy(self):
        return self.values.copy()


class _FakeEngine:
    """Two instances (three slots: one of padding): each step adds 3 and 5 Newton iterations
    and 2 and 1 factorisations; `load` puts the counters back to 0; instance 1 fails at step
    `fail_at` (never by default)."""

    n_nodes = 193  # the paper robot's: the work checks weigh it (timegrid.step_work)

    def __init__(self, fail_at=None):
        self.loads, self.launches, self.fail_at = 0, [], fail_at
        self.state = SimpleNamespace(newton_total=_Array([0, 0, 0]),
                                     factorisations=_Array([0, 0, 0]),
                                     status=_Array([0, 0, 0]))
        self.steps = 0

    def load(self, model, solver):
        self.loads += 1
        self.steps = 0
        self.state.newton_total.values[:] = 0
        self.state.factorisations.values[:] = 0
        self.state.status.values[:] = 0

    def advance(self, count):
        self.launches.append(count)
        for _ in range(count):
            self.steps += 1
            self.state.newton_total.values[:2] += (3, 5)
            self.state.factorisations.values[:2] += (2, 1)
            if self.fail_at is not None and self.steps >= self.fail_at:
                self.state.status.values[1] = 2


def _profile(monkeypatch, engine):
    profile = profiling.EngineProfile.__new__(profiling.EngineProfile)
    profile.model = SimpleNamespace(batch_size=2)
    profile.solver = ts.SolverConfig()
    profile._engine = engine
    monkeypatch.setattr(profiling.ti, "sync", lambda: None)
    monkeypatch.setattr(runtime_module.Runtime, "check_engine_usable", lambda self, e: None)
    return profile


def test_a_timed_window_restarts_and_counts_per_instance_step_of_its_own_steps(monkeypatch):
    """From rest (a `load`), warm-up steps left out; (3 + 5)/2 = 4 iterations and
    (2 + 1)/2 = 1.5 factorisations per instance-step, whatever ran before."""
    engine = _FakeEngine()
    profile = _profile(monkeypatch, engine)
    profile.advance(7)  # steps before the window: not counted, and not from rest
    _, iterations, factorisations = profile.timed_window(4, 10)
    assert engine.loads == 1 and engine.steps == 14
    assert iterations == 4.0 and factorisations == 1.5


def test_a_timed_window_with_a_failed_instance_is_refused(monkeypatch):
    """An instance that failed in the window makes its timing invalid."""
    profile = _profile(monkeypatch, _FakeEngine(fail_at=6))
    with pytest.raises(RuntimeError, match="an instance failed during the benchmark"):
        profile.timed_window(2, 10)


def test_advance_launches_in_simulates_chunks(monkeypatch):
    """STEPS_PER_LAUNCH steps a launch, the rest in a last one, never an extra."""
    from taichi_star.timegrid import STEPS_PER_LAUNCH
    engine = _FakeEngine()
    _profile(monkeypatch, engine).advance(2 * STEPS_PER_LAUNCH + 3)
    assert engine.launches == [STEPS_PER_LAUNCH, STEPS_PER_LAUNCH, 3]


def test_first_launch_never_reports_a_negative_compile_time(monkeypatch):
    """A first launch faster than the second (noise) gives compile_s 0, not below."""
    clock = iter([0.0, 1.0, 10.0, 12.0])  # first launch 1 s, the second 2 s
    profile = _profile(monkeypatch, _FakeEngine())
    monkeypatch.setattr(profiling.time, "perf_counter", lambda: next(clock))
    assert profile.first_launch() == (0.0, 1.0)


def test_phase_split_is_microseconds_per_instance_and_iteration_of_each_phase(monkeypatch):
    """With launches whose time is exactly calls × batch × the cumulative µs of their phases
    (residual 1, +Jacobian 3, +factor 10, +solve 12), the split is residual 1, assembly 3,
    factor 7, solve 2 µs; each launch repeats round(profile_seconds / iteration_s) times, at
    least 1 and at most MAX_PROFILE_CALLS."""
    clock = [0.0]
    cumulative = {0: 1.0, 1: 3.0, 2: 10.0, 3: 12.0}
    seen = []

    def launch(engine, phases, calls, time_s):
        seen.append(calls)
        clock[0] += cumulative[phases] * 1e-6 * calls * 2  # two instances

    monkeypatch.setattr(profiling, "_profile_phases", launch)
    monkeypatch.setattr(profiling.time, "perf_counter", lambda: clock[0])
    profile = _profile(monkeypatch, _FakeEngine())
    split = profile.phase_split(0.01, iteration_s=1e-3, profile_seconds=0.0503)
    assert split == pytest.approx({"residual": 1.0, "assembly": 3.0, "factor": 7.0,
                                   "solve": 2.0}, rel=1e-9)
    assert seen == [1] + [50] * 4 * profiling.PROFILE_LAUNCHES  # the compiling launch first
    seen.clear()
    profile.phase_split(0.01, iteration_s=1.0, profile_seconds=1e-9)
    assert set(seen) == {1}
    seen.clear()
    profile.phase_split(0.01, iteration_s=1e-9, profile_seconds=1.0)
    assert set(seen[1:]) == {profiling.MAX_PROFILE_CALLS}


@pytest.mark.parametrize("precision, scalar", [("f64", 8), ("f32", 4)])
def test_matrix_bytes_per_iteration_are_those_of_the_precision(monkeypatch, precision, scalar):
    """4 passes over n_slots 2×2 blocks and 6 over the n_nodes × 2 right-hand side and
    positions, of 8-byte scalars in f64 and 4-byte ones in f32."""
    engine = _FakeEngine()
    engine.plan, engine.n_nodes = SimpleNamespace(n_slots=10), 3
    profile = _profile(monkeypatch, engine)
    profile.solver = ts.SolverConfig(precision=precision, newton_tol=1e-6)
    assert profile.matrix_bytes_per_iteration() == scalar * (4 * 10 * 4 + 6 * 3 * 2)
