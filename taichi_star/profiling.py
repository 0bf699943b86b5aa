"""Profiling of the batch engine, for benchmarks (`python -m studies bench`).

`EngineProfile` drives one batch's engine directly, as `simulate` does with fixed steps, and
measures what a benchmark reports: the setup (Taichi initialisation, the engine built or reused,
the batch loaded), the first launch (compilation, `first_launch`), timed windows of steps from
rest (`timed_window`), the split of a Newton iteration into assembly, factorisation and solve
(`phase_split`, by groups in an engine with lanes), and the engine's facts (its terms, node
count, Jacobian blocks, the FLOPs of one factorisation); `device_bandwidth` measures a GPU's
memory bandwidth and `matmul_gflops` NumPy's matrix-product rate (the CPU's attainable
floating-point rate); `interleaved_rounds` times whole calls (a `simulate`, a `run_batch`)
against each other, in rounds after a warm-up of each.

All times are wall-clock seconds of the whole machine (so they include the parallel speed-up
over cores).
"""

import math
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
import taichi as ti

from .checks import check_choice, is_whole
from .model import build_model, validate_batch
from .params import PRECISIONS, SolverConfig, StarParams, check_precision
from .runtime import Runtime, check_arch, one_call_at_a_time
from .state import STATUS_OK
from .timegrid import STEPS_PER_LAUNCH, check_work

# the public names (docs/api.md), those the studies use among them (tests/test_layering.py)
__all__ = ["EngineProfile", "step_phases", "matmul_gflops", "device_bandwidth",
           "interleaved_rounds"]

PROFILE_LAUNCHES = 3
"""`phase_split` times each phase as the best of this many launches (the differences of noisy
timings would be noisier still)."""
MAX_PROFILE_CALLS = 10_000
"""Most repetitions of a phase in one profiling launch."""
BANDWIDTH_BYTES = 1 << 30
"""Size of the buffer `device_bandwidth` copies (bytes): far larger than any cache."""


@ti.func
def _begin_profile_step(engine: ti.template(), b, time_s, rate_gain):
    """The terms' step start of instance b for an implicit Euler step of size dt ending at
    time_s (s), `rate_gain` that step's (`integrator.weights`)."""
    h = engine.dt[None]
    for term in ti.static(engine.terms):
        term.begin_step(b, time_s - h, time_s, h, 1.0, rate_gain, 0)


@ti.kernel
def _profile_phases(engine: ti.template(), phases: ti.i32, calls: ti.i32, time_s: float):
    """For every live instance of `engine`, `calls` times: assemble the residual of an implicit
    Euler step of size dt ending at time_s (s) at the current state, and its Jacobian when
    phases >= 1 (phases = 0: the residual alone, as a chord iteration does), then factor when
    phases >= 2, then solve when phases >= 3, as the engine's fixed steps do: one instance at a
    time, or in an engine with lanes by groups (`engine.BatchEngine.advance_group`: every
    member assembles its own system, then the group's systems are gathered into the lanes and
    factored there, then solved there and scattered back, in lockstep; each on its own
    otherwise). Changes the terms' step histories (not the positions). The instances (groups)
    are spread over the loop as the engine's own step spreads them (`slot_instance`,
    `slot_group`), so that the profile runs on as many cores as the step it splits."""
    jacobian = 1 if phases >= 1 else 0
    ti.loop_config(block_dim=engine.instances_per_block)
    for slot in range(engine.capacity * engine.loop_spread):
        inertia_scale, rate_gain = engine.integrator.weights(engine.dt[None], 1.0, 0)
        if ti.static(engine.lanes > 1):
            g = engine.slot_group(slot)
            if g >= 0:
                for lane in range(engine.lanes):
                    b = engine.group_member(g, lane)
                    if b >= 0:
                        _begin_profile_step(engine, b, time_s, rate_gain)
                members = engine.group_members(g)
                for _ in range(calls):
                    for lane in range(engine.lanes):
                        b = engine.group_member(g, lane)
                        if b >= 0 and engine.state.status[b] == STATUS_OK:
                            engine.assemble(b, inertia_scale, rate_gain, jacobian)
                    if engine.lockstep[None] == 1:
                        if phases >= 2:
                            engine.lane_system.gather(g, members)
                            engine.lane_system.factor(g)
                        if phases >= 3:
                            engine.lane_system.solve(g)
                            engine.lane_system.scatter_solution(g, members)
                    else:
                        for lane in range(engine.lanes):
                            b = engine.group_member(g, lane)
                            if b >= 0 and engine.state.status[b] == STATUS_OK:
                                if phases >= 2:
                                    engine.system.factor(b)
                                if phases >= 3:
                                    engine.system.solve(b)
        else:
            b = engine.slot_instance(slot)
            if b >= 0 and engine.state.status[b] == STATUS_OK:
                _begin_profile_step(engine, b, time_s, rate_gain)
                for _ in range(calls):
                    engine.assemble(b, inertia_scale, rate_gain, jacobian)
                    if phases >= 2:
                        engine.system.factor(b)
                    if phases >= 3:
                        engine.system.solve(b)


def _check_steps(name: str, value, lowest: int, batch: int, nodes: int):
    """ValueError naming `name` unless `value` is an integer >= lowest and within the step
    counter (`timegrid.check_work` for `batch` instances of `nodes` nodes)."""
    if not is_whole(value) or value < lowest:
        raise ValueError(f"{name} must be an integer >= {lowest}, got {value!r}")
    check_work(f"{name} = {value}", value, batch, nodes=nodes)


class EngineProfile:
    """The engine of one batch (`params`, a sequence of StarParams; `solver`, fixed steps) on
    `arch`, loaded at rest, its own while the profile lives (as a Simulator's: no call or
    Simulator uses it meanwhile; a precision switch is refused), each method holding the
    runtime's lock (`runtime.one_call_at_a_time`). `setup_s`: the time this took (Taichi
    initialised if it was not, the engine built or taken from the runtime's cache, the batch
    loaded)."""

    @one_call_at_a_time
    def __init__(self, params: Sequence[StarParams], solver: SolverConfig = SolverConfig(),
                 arch: str = "cpu"):
        if not isinstance(solver, SolverConfig):
            raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
        if solver.adaptive:
            raise ValueError("solver: EngineProfile times fixed steps; got an adaptive solver "
                             "(profile it end to end with simulate)")
        # refused before the model is built or Taichi started, as `simulate` refuses them
        params = validate_batch(params)
        check_precision(params, solver)
        check_arch(arch)
        start = time.perf_counter()
        self.model = build_model(params)
        self.solver = solver
        runtime = Runtime.current()
        runtime.ensure(arch, solver.precision)
        # its own while it lives, as a Simulator's: a call or Simulator of the same batch drew
        # it too and moved its robots, a precision switch destroyed it (an audit, 2026-12)
        self._engine = runtime.lease_engine(self.model, solver, self)
        self._engine.load(self.model, solver)
        ti.sync()
        self.setup_s = time.perf_counter() - start

    @property
    def engine(self):
        """The engine it times (`engine.BatchEngine`). RuntimeError where a `ti.init` outside
        this package destroyed it, or in a forked process (`runtime.Runtime
        .check_engine_usable`: it ran a destroyed engine, as a Simulator did: a review,
        2026-12)."""
        Runtime.current().check_engine_usable(self._engine)
        return self._engine

    @property
    def batch_size(self) -> int:
        return self.model.batch_size

    @property
    def terms(self) -> Tuple[str, ...]:
        """The force terms the engine was compiled with, in registry order."""
        return tuple(term.name for term in self.engine.terms)

    @property
    def n_nodes(self) -> int:
        return self.engine.n_nodes

    @property
    def lanes(self) -> int:
        """Instances per group of the engine's fixed-step kernel (`runtime.Runtime.engine_lanes`;
        1: one at a time)."""
        return self.engine.lanes

    @property
    def n_slots(self) -> int:
        """2×2 blocks of the Newton matrix's elimination pattern (fill-in included)."""
        return self.engine.plan.n_slots

    @property
    def elimination_plan(self):
        """The host-side symbolic factorisation of the engine's Newton matrix (its 2×2 block
        pattern with fill-in, elimination order and the flat list of block operations of the
        numeric LU; a frozen `EliminationPlan` of NumPy index tables), for prototypes of the
        factorisation kernel (`python -m studies simd`)."""
        return self.engine.plan

    @property
    def factor_flops(self) -> int:
        """Floating-point operations of one numeric factorisation of one instance."""
        return self.engine.plan.factor_flops

    def matrix_bytes_per_iteration(self) -> float:
        """Device-memory bytes of one Newton iteration of one instance when the matrix lives in
        device memory: the 2×2 blocks written by the assembly, read and written by the in-place
        LU and read by the solve (4 times), the right-hand side written and read twice,
        positions read and written."""
        scalar = 8 if self.solver.precision == "f64" else 4
        return 4 * self.n_slots * 4 * scalar + 6 * self.n_nodes * 2 * scalar

    @one_call_at_a_time
    def restart(self):
        """Every instance back at rest, as after loading."""
        self.engine.load(self.model, self.solver)

    @one_call_at_a_time
    def advance(self, n_steps: int):
        """n_steps steps of every live instance, in launches of `simulate`'s size; finished
        (synchronised) when this returns. ValueError naming n_steps unless it is an integer >= 0
        within the step counter (`timegrid.check_work`)."""
        _check_steps("n_steps", n_steps, 0, self.batch_size, self.n_nodes)
        done = 0
        while done < n_steps:
            count = min(STEPS_PER_LAUNCH, n_steps - done)
            self.engine.advance(count)
            done += count
        ti.sync()

    @one_call_at_a_time
    def first_launch(self) -> Tuple[float, float]:
        """(compile_s, first_s): the first one-step launch (compilation and a step), less the
        time of a second one-step launch. Call it once, before any other stepping."""
        first = time.perf_counter()
        self.advance(1)
        first = time.perf_counter() - first
        again = time.perf_counter()
        self.advance(1)
        again = time.perf_counter() - again
        return max(first - again, 0.0), first

    @one_call_at_a_time
    def newton_iterations(self) -> np.ndarray:
        """(B,) Newton iterations of every instance so far."""
        return self.engine.state.newton_total.to_numpy()[:self.batch_size]

    @one_call_at_a_time
    def factorisations(self) -> np.ndarray:
        """(B,) Newton matrices assembled and factored by every instance so far (one per
        iteration with Newton's Jacobian, fewer with the chord's)."""
        return self.engine.state.factorisations.to_numpy()[:self.batch_size]

    @one_call_at_a_time
    def positions(self) -> np.ndarray:
        """(B, N, 2) node positions now, m (the engine's precision)."""
        return self.engine.state.positions.to_numpy()[:self.batch_size]

    @one_call_at_a_time
    def timed_window(self, warmup_steps: int, steps: int) -> Tuple[float, float, float]:
        """From rest, `warmup_steps` untimed steps, then `steps` timed ones: (seconds, Newton
        iterations and factorisations per instance-step of the timed steps). RuntimeError if
        an instance failed (the timing would not be valid). ValueError naming warmup_steps
        (an integer >= 0) or steps (>= 1) otherwise, or the two together past the step
        counter."""
        _check_steps("warmup_steps", warmup_steps, 0, self.batch_size, self.n_nodes)
        _check_steps("steps", steps, 1, self.batch_size, self.n_nodes)
        check_work(f"warmup_steps + steps = {warmup_steps + steps}", warmup_steps + steps,
                   self.batch_size, nodes=self.n_nodes)
        self.restart()
        self.advance(warmup_steps)
        iterations, factorisations = self.newton_iterations().sum(), self.factorisations().sum()
        start = time.perf_counter()
        self.advance(steps)
        seconds = time.perf_counter() - start
        if (self.engine.state.status.to_numpy()[:self.batch_size] != STATUS_OK).any():
            raise RuntimeError("an instance failed during the benchmark: its timing is not valid")
        instance_steps = self.batch_size * steps
        return (seconds, (self.newton_iterations().sum() - iterations) / instance_steps,
                (self.factorisations().sum() - factorisations) / instance_steps)

    @one_call_at_a_time
    def phase_split(self, time_s: float, iteration_s: float, profile_seconds: float) -> Dict[str, float]:
        """µs per instance and Newton iteration of the assembly, the factorisation and the
        solve as the engine's fixed steps run them (in an engine with lanes by groups, the
        factorisation's share including the copy of a group's systems into its lanes), and of
        the residual's assembly alone (`residual`: the part of `assembly` that does not come
        from the Jacobian's derivatives and blocks), at the current state of every live
        instance (its step ending at time_s, s): from launches that repeat the residual's
        assembly, the assembly, assembly + factorisation, and assembly + factorisation + solve
        (the factorisation is in place, so it always needs a fresh assembly), each the best of
        PROFILE_LAUNCHES; `iteration_s` (one Newton iteration of the batch, s) sizes the
        repetitions to about `profile_seconds` per launch. Changes the terms' step histories,
        not the positions."""
        calls = int(min(max(round(profile_seconds / iteration_s), 1), MAX_PROFILE_CALLS))
        _profile_phases(self.engine, 3, 1, time_s)  # compile outside the timings
        ti.sync()
        cumulative = []
        for phases in (0, 1, 2, 3):
            best = math.inf
            for _ in range(PROFILE_LAUNCHES):
                start = time.perf_counter()
                _profile_phases(self.engine, phases, calls, time_s)
                ti.sync()
                best = min(best, time.perf_counter() - start)
            cumulative.append(best * 1e6 / (self.batch_size * calls))
        return {"residual": cumulative[0], "assembly": cumulative[1],
                "factor": cumulative[2] - cumulative[1], "solve": cumulative[3] - cumulative[2]}


def step_phases(phase: Dict[str, float], iterations: float,
                factorisations: float) -> Dict[str, float]:
    """µs per instance-step of the residual, the assembly (residual included), the
    factorisation and the solve, from `EngineProfile.phase_split`'s µs per Newton iteration
    (`phase`) and the step's mean Newton `iterations` and `factorisations`: every iteration
    assembles its residual and solves, the iterations that refresh the Newton matrix (all of
    them with Newton's Jacobian, fewer with the chord's) also assemble the Jacobian and
    factor."""
    residual = iterations * phase["residual"]
    return {"residual": residual,
            "assembly": residual + factorisations * (phase["assembly"] - phase["residual"]),
            "factor": factorisations * phase["factor"], "solve": iterations * phase["solve"]}


def interleaved_rounds(calls: Sequence[Callable[[], object]], rounds: int,
                       warmups: Optional[Sequence[Optional[Callable[[], object]]]] = None,
                       before_rounds: Optional[Callable[[], object]] = None,
                       progress: Optional[Callable[[int, int, float], object]] = None
                       ) -> Tuple[List[object], np.ndarray, np.ndarray]:
    """Time K calls (functions of no argument) against each other in interleaved rounds.

    First a warm-up of each call, in order: `warmups[k]()`, or `calls[k]()` itself where that
    entry (or `warmups`) is None. A warm-up starts and compiles what call k needs (Taichi's
    kernels, worker processes), so that no round pays for it, and its time is kept apart from
    the rounds'; a one-step `simulate` of the same batch and solver is one. Then
    `before_rounds()` if given (e.g. a reading of the machine's load just before the timings),
    then `rounds` rounds that each make every call once, in order, so that the machine's
    drifts (other jobs, clock speeds) reach them all alike; `progress(round, k, seconds)` after
    each timed call if given (round and k from 0).

    Returns (results, times, warmup_times): each call's result in the last round (a list of
    K), the wall time of every timed call, s, a (rounds, K) array (`times.min(axis=0)`: each
    call's best, the least disturbed by the rest of the machine), and each warm-up's wall time,
    s, a (K,) array. Wall-clock seconds of `time.perf_counter`.

    ValueError naming calls (empty), rounds (not an integer >= 1) or warmups (not K entries).
    """
    calls = list(calls)
    if not calls:
        raise ValueError("calls must hold at least one call, got none")
    if not is_whole(rounds) or rounds < 1:
        raise ValueError(f"rounds must be an integer >= 1, got {rounds!r}")
    warmups = [None] * len(calls) if warmups is None else list(warmups)
    if len(warmups) != len(calls):
        raise ValueError(f"warmups must have one entry per call ({len(calls)}, None: the call "
                         f"itself), got {len(warmups)}")
    warmup_times = np.empty(len(calls))
    for index, (call, warmup) in enumerate(zip(calls, warmups)):
        start = time.perf_counter()
        (warmup or call)()
        warmup_times[index] = time.perf_counter() - start
    if before_rounds is not None:
        before_rounds()
    times = np.empty((rounds, len(calls)))
    results = [None] * len(calls)
    for round_index in range(rounds):
        for index, call in enumerate(calls):
            start = time.perf_counter()
            results[index] = call()
            seconds = time.perf_counter() - start
            times[round_index, index] = seconds
            if progress is not None:
                progress(round_index, index, seconds)
    return results, times, warmup_times


def matmul_gflops(size: int, precision: str, rng: np.random.Generator) -> float:
    """NumPy's size × size matrix product in precision ("f64" or "f32"), GFLOP/s (best of 3, of
    random normal matrices from `rng`): the machine's attainable floating-point rate, the
    reference a benchmark sets its kernels' GFLOP/s against. ValueError for a size that is not
    a whole number >= 1 or another precision (f16 ran in f32, a size of 0 gave 0 GFLOP/s: an
    audit)."""
    if not is_whole(size) or size < 1:
        raise ValueError(f"size must be a whole number >= 1, got {size!r}")
    check_choice("precision", precision, PRECISIONS)
    size = int(size)
    dtype = np.float64 if precision == "f64" else np.float32
    a, b = (rng.standard_normal((size, size)).astype(dtype) for _ in range(2))
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        np.dot(a, b)
        best = min(best, time.perf_counter() - start)
    return 2 * size ** 3 / best / 1e9


def device_bandwidth(arch: str, precision: str) -> float:
    """Device-memory bandwidth of a GPU arch, GB/s (bytes read + written by a Taichi copy
    kernel of BANDWIDTH_BYTES, best of 5), or NaN on the CPU (not a figure the CPU needs).
    Initialises Taichi for arch and precision."""
    if arch == "cpu":
        return math.nan
    Runtime.current().ensure(arch, precision)
    count = BANDWIDTH_BYTES // 4
    source = ti.field(ti.f32, count)
    target = ti.field(ti.f32, count)

    @ti.kernel
    def copy():
        for i in range(count):
            target[i] = source[i]

    source.fill(1.0)
    copy()
    ti.sync()
    best = math.inf
    for _ in range(5):
        start = time.perf_counter()
        copy()
        ti.sync()
        best = min(best, time.perf_counter() - start)
    return 2 * BANDWIDTH_BYTES / best / 1e9
