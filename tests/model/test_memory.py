"""The memory guard: an engine's size is known before it is allocated, and a batch too large for
the machine is refused with the way to run it (chunks) instead of exhausting memory."""

import gc
import warnings

import pandas as pd
import pytest

import taichi_star as ts
from taichi_star import runtime
from taichi_star.model import build_model
from taichi_star.runtime import engine_bytes, prepare_engine


class Ran(Exception):
    """The run got past the checks (stubbed: nothing is simulated)."""


def ran(*args, **kwargs):
    """A stand-in for the first step after the checks: it raises Ran."""
    raise Ran


@pytest.mark.parametrize("preset", ["paper", "accurate"])
def test_engine_size_estimate_matches_the_fields_allocated(preset, taichi_cpu):
    """The estimate counts the per-instance fields; the engine's shared index tables (a few
    hundred kB, independent of the batch) are what it leaves out: within 2 % at capacity 64."""
    params = [ts.StarParams.preset(preset, gait="A1+A3")] * 3
    engine = prepare_engine(params, ts.SolverConfig.preset(preset))
    estimate = engine_bytes(build_model(params), "f64")
    assert abs(estimate / engine.arena.nbytes - 1.0) <= 0.02, (estimate, engine.arena.nbytes)


def test_a_large_batch_is_streamed_in_chunks_that_fit_the_memory(monkeypatch):
    """With 100 MiB available (budget 80 %), 5,000 instances are cut into equal chunks whose
    engine fits the budget but would not at twice the size (the planner takes the largest power
    of two that fits)."""
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: 100 * 2**20)
    params = [ts.StarParams()] * 5000
    chunk = runtime.stream_chunk_size(params, "f64", "cpu")
    budget = runtime.MEMORY_SHARE * 100 * 2**20
    assert engine_bytes(build_model(params[:chunk]), "f64") <= budget
    assert engine_bytes(build_model(params[:2 * runtime.batch_capacity(chunk)]), "f64") > budget
    assert len(range(0, 5000, chunk)) == -(-5000 // runtime.batch_capacity(chunk))


def test_a_sensitive_batch_is_streamed_in_equal_chunks_of_whole_robots(monkeypatch):
    """Each robot with one sensitivity is three instances: with room for 128 instances, 100
    robots ran as 33, 33, 33 and 1 (the instances' chunks rounded down to whole robots: a
    review, 2026-12); now as three chunks of 34 (102 instances), 33 and 33 alone one fewer."""
    robots = [ts.StarParams(n_arc=6, n_limb=2)] * 100
    probe = build_model(robots[:runtime.MIN_CAPACITY])
    per_instance = engine_bytes(probe, "f64") / runtime.batch_capacity(probe.batch_size)
    monkeypatch.setattr(runtime, "CPU_ENGINE_BUDGET_BYTES", 128 * per_instance)
    assert runtime.stream_chunk_size(robots, "f64", "cpu", replicas=3) == 34
    assert runtime.stream_chunk_size(robots[:84], "f64", "cpu", replicas=3) == 42  # 126
    assert runtime.stream_chunk_size(robots, "f64", "cpu") == 100  # 100 instances fit
    assert runtime.stream_chunk_size(robots[:21], "f64", "cpu", replicas=3) == 21  # 63
    # 43 robots are 129 instances, past the smallest engine's 64: cut, by their instances
    assert runtime.stream_chunk_size(robots[:43], "f64", "cpu", replicas=3) == 22
    # a robot of more instances than the room (64 directions) still runs, alone
    assert runtime.stream_chunk_size(robots[:2], "f64", "cpu", replicas=129) == 1


def test_the_memory_check_counts_the_engine_a_batch_is_built_in(monkeypatch):
    """A streamed batch's last chunk runs in the first chunk's engine (`least_batch`): 64
    robots built as for 65 take the engine of capacity 128, and that is the one the check
    must find room for."""
    model = build_model([ts.StarParams(n_arc=6, n_limb=2)] * 64)
    own, shared = engine_bytes(model, "f64"), engine_bytes(model, "f64", 65)
    assert shared > own
    monkeypatch.setattr(runtime, "available_memory_bytes",
                        lambda: (own + shared) / 2 / runtime.MEMORY_SHARE)
    runtime.check_memory(model, "f64", "cpu")  # its own engine fits
    with pytest.raises(ValueError, match="for its engine, more than"):
        runtime.check_memory(model, "f64", "cpu", least_batch=65)


def test_a_machine_without_room_for_the_smallest_engine_refuses_before_compute(monkeypatch):
    """With 1 MiB available even the 64-instance engine (~7 MB) does not fit: a ValueError
    naming the budget, and no engine is cached (a topology no other test builds, so that no
    engine of it is cached already)."""
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: 2**20)
    before = set(runtime.Runtime.current().engines)
    with pytest.raises(ValueError, match=r"params: a batch of 3 .*the memory budget"):
        ts.simulate([ts.StarParams(n_arc=11)] * 3, 0.001)
    assert set(runtime.Runtime.current().engines) == before


@pytest.mark.parametrize("sensitivities, replicas", [((), 1), (("alpha",), 3)])
def test_records_that_would_not_fit_in_memory_are_refused_before_compute(monkeypatch,
                                                                           memory_budget,
                                                                           sensitivities,
                                                                           replicas):
    """A run's records were never estimated: 2e9 records of one robot failed listing its stops,
    512 robots' shapes after 26 s of compute (an audit). Now the host memory of the records is
    estimated (`simulation.RECORD_ROW_BYTES` a record of an instance, RECORD_NODE_BYTES a node
    of its shape, RECORD_BYTES a record) with the summary's (SUMMARY_ROW_BYTES a row), in one
    sum (checked apart, each could take the whole budget: an audit), and refused past
    MEMORY_SHARE of the available memory, before anything runs: at the budget accepted, a
    byte over refused. A sensitive run (one direction: each instance and its two replicas)
    counts its replicas' summary and trajectory rows, not their shapes (the replicas' are not
    kept): counted without them, it passed the check short of its need."""
    from taichi_star import simulation
    params = [ts.StarParams()] * 4
    records = 11  # 0.1 s every 10 ms, the start included
    needed = 4 * replicas * simulation.SUMMARY_ROW_BYTES + records * (
        4 * (replicas * simulation.RECORD_ROW_BYTES + 193 * simulation.RECORD_NODE_BYTES)
        + simulation.RECORD_BYTES)
    monkeypatch.setattr(simulation, "_simulate_chunk", ran)
    for refused in memory_budget(needed):
        if refused:
            with pytest.raises(ValueError, match=rf"^record_interval_s: the summary and 11 "
                                                 rf"records of {4 * replicas} instances with "
                                                 rf"their shapes would need about "):
                ts.simulate(params, 0.1, record_interval_s=0.01, record_shapes=True,
                            sensitivities=sensitivities)
        else:
            with pytest.raises(Ran):
                ts.simulate(params, 0.1, record_interval_s=0.01, record_shapes=True,
                            sensitivities=sensitivities)


@pytest.mark.parametrize("warn_robot_steps, warned", [(1199, True), (1200, False)])
def test_a_sensitive_runs_long_work_warning_counts_its_replicas(monkeypatch, warn_robot_steps,
                                                                warned):
    """The long-run warning counts the instances simulated: 4 instances with one direction
    are 12, 1,200 robot-steps in 0.1 s of 1-ms steps, warned past WARN_ROBOT_STEPS (1,199), not
    at it (1,200); the 400 of the instances asked for alone would stay under both."""
    from taichi_star import simulation, timegrid
    monkeypatch.setattr(simulation, "_simulate_chunk", ran)
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", warn_robot_steps)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        with pytest.raises(Ran):
            ts.simulate([ts.StarParams()] * 4, 0.1, sensitivities=["alpha"])
    messages = [str(w.message) for w in caught if w.category is ts.LongWorkWarning]
    assert messages == ([f"duration_s = 0.1 s at dt = 0.001 s is 1.2e+03 robot-steps: about "
                         f"{1200 / 5e4 / 3600:.3g} h at 50000 robot-steps/s (on a 2-core CPU; "
                         f"a GPU or more cores run faster)"] if warned else [])


def test_a_simulators_records_that_would_not_fit_are_refused_before_it_steps(monkeypatch):
    """`Simulator.advance` estimates its records (`simulator.STATE_ROW_BYTES` a record of an
    instance, STATE_RECORD_BYTES a record) the same way; the state is left as it was."""
    from taichi_star import simulator as simulator_module
    robots = ts.Simulator([ts.StarParams()] * 2)
    needed = 10 * (2 * simulator_module.STATE_ROW_BYTES + simulator_module.STATE_RECORD_BYTES)
    monkeypatch.setattr(runtime, "available_memory_bytes",
                        lambda: (needed - 1) / runtime.MEMORY_SHARE)
    with pytest.raises(ValueError, match=r"^record_interval_s: 10 records of 2 instances would "):
        robots.advance(0.1, record_interval_s=0.01)
    assert (robots.time_s == 0).all()
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: needed / runtime.MEMORY_SHARE)
    assert len(robots.advance(0.1, record_interval_s=0.01)) == 20


def test_a_batchs_summary_and_a_simulators_engine_are_estimated_before_they_are_built(
        monkeypatch, memory_budget):
    """10^8 robots ran for hours towards a summary of ~95 GiB, and a Simulator of 10^6 built
    its model for 49 s and 6 GB, then failed in NumPy (an audit). Now `simulate` estimates the
    summary (`simulation.SUMMARY_ROW_BYTES` a row; measured 659) and a Simulator its engine
    and model from its first MIN_CAPACITY instances' model (`runtime.check_batch_memory`),
    refused past the budget before anything is built, at it accepted."""
    from taichi_star import simulation

    monkeypatch.setattr(simulation, "_simulate_chunk", ran)
    params = [ts.StarParams()] * 100
    for refused in memory_budget(100 * simulation.SUMMARY_ROW_BYTES):
        if refused:
            with pytest.raises(ValueError, match=r"^params: the summary of 100 instances would "
                                                 r"need about "):
                ts.simulate(params, 0.01)
        else:
            with pytest.raises(Ran):
                ts.simulate(params, 0.01)
    probe = build_model(params[:runtime.MIN_CAPACITY])
    engine = (engine_bytes(probe, "f64") / runtime.batch_capacity(runtime.MIN_CAPACITY)
              * runtime.batch_capacity(100) + probe.nbytes / runtime.MIN_CAPACITY * 100)
    built = []
    monkeypatch.setattr(runtime.Runtime, "lease_engine", lambda *args, **kwargs: built.append(1))
    monkeypatch.setattr(runtime, "available_memory_bytes",
                        lambda: (engine - 1) / runtime.MEMORY_SHARE)
    with pytest.raises(ValueError, match=r"^params: an engine and model of 100 instances would "):
        ts.Simulator(params)
    assert not built
    # off the CPU the engine is on the device: the model's host memory alone is counted (it
    # was not checked at all)
    model = probe.nbytes / runtime.MIN_CAPACITY * 100
    monkeypatch.setattr(runtime, "available_memory_bytes",
                        lambda: (model - 1) / runtime.MEMORY_SHARE)
    with pytest.raises(ValueError, match=r"^params: a model of 100 instances would need "):
        runtime.check_batch_memory(params, "f64", "gpu")
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: model / runtime.MEMORY_SHARE)
    runtime.check_batch_memory(params, "f64", "gpu")


def test_a_sensitive_simulators_engine_and_model_count_its_replicas(monkeypatch, memory_budget):
    """A Simulator of 100 instances with one direction builds an engine and model of 300 (each
    instance and its two replicas): its estimate is theirs, at the budget accepted, a byte over
    refused (counted without the replicas, as 100, it passed short of its need)."""
    from taichi_star import sensitivities as tangents
    params = [ts.StarParams()] * 100
    probe = build_model(params[:runtime.MIN_CAPACITY])
    needed = (engine_bytes(probe, "f64") / runtime.batch_capacity(runtime.MIN_CAPACITY)
              * runtime.batch_capacity(300) + probe.nbytes / runtime.MIN_CAPACITY * 300)
    monkeypatch.setattr(tangents, "replica_model", ran)  # the model is built after the check
    for refused in memory_budget(needed):
        if refused:
            with pytest.raises(ValueError, match=r"^params: an engine and model of 300 "
                                                 r"instances would need about "):
                ts.Simulator(params, sensitivities=["alpha"])
        else:
            with pytest.raises(Ran):
                ts.Simulator(params, sensitivities=["alpha"])


@pytest.mark.parametrize("count, refused", [(runtime.MIN_CAPACITY, False),
                                            (runtime.MIN_CAPACITY + 1, True)])
def test_a_batch_the_smallest_engine_holds_is_left_to_check_memory(monkeypatch, count,
                                                                   refused):
    """`check_batch_memory` estimates batches larger than the smallest engine (MIN_CAPACITY
    instances) from the first MIN_CAPACITY instances' model; up to that size it leaves the
    batch to `check_memory`, on the model itself: with a byte available, 64 instances pass it
    and 65 are refused."""
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: 1.0)
    if refused:
        with pytest.raises(ValueError, match=rf"^params: an engine and model of {count} "
                                             rf"instances would need about "):
            runtime.check_batch_memory([ts.StarParams()] * count, "f64", "cpu")
    else:
        runtime.check_batch_memory([ts.StarParams()] * count, "f64", "cpu")


def test_engines_past_the_budget_are_destroyed_least_recently_used_first(monkeypatch):
    """Every engine a process built was kept: calls of 1,000, 2,000 and 3,000 robots kept
    their fields, 1.1 GB (an audit). Past FREE_ENGINES_BYTES the least recently used engines
    that no Simulator holds are destroyed, the one a call uses kept; a batch whose engine went
    is built again, with the same bits; `release_engines` gives back all but those held. An
    engine a call reuses counts as used then, not when it was built. A Simulator's engine
    counts as used when the Simulator goes (it kept its lease's stamp, and went before the
    engines of calls made meanwhile: a review, 2026-12). Three capacities of one coarse robot
    (64, 128, 256: fields about 1 : 2 : 4) in a cache of their own, with room for the two
    largest. The robot has no fluid terms: its five builds compile ~20 % faster (the suite's
    time; what is kept and destroyed does not depend on the terms)."""
    current = runtime.Runtime.current()
    monkeypatch.setattr(current, "engines", {})
    robot = ts.StarParams(gait="A1", n_arc=6, n_limb=2, alpha=0.0, added_mass_coeff=0.0,
                          drag_parallel=0.0, drag_perpendicular=0.0, cylinder_drag=0.0)
    small, middle, large = ([robot] * count for count in (1, 65, 129))
    ts.simulate(small, 0.002)
    first = ts.simulate(middle, 0.002)
    ts.simulate(small, 0.002)  # reused: the 128's is now the least recently used
    sizes = {len(batch): engine_bytes(build_model(batch), "f64") for batch in (small, large)}
    (middle_slot,) = (slot for slots in current.engines.values() for slot in slots
                      if slot.engine.capacity == 128)
    budget = middle_slot.engine.arena.nbytes + 1.1 * sizes[129]
    monkeypatch.setattr(runtime, "FREE_ENGINES_BYTES", budget)

    def capacities():
        return sorted(slot.engine.capacity for slots in current.engines.values()
                      for slot in slots)

    assert capacities() == [64, 128]
    ts.simulate(large, 0.002)
    assert capacities() == [64, 256]  # the 128's, least recently used, went
    again = ts.simulate(middle, 0.002)  # built again: the 64's goes
    assert capacities() == [128, 256]
    pd.testing.assert_frame_equal(again.summary, first.summary, check_exact=True)
    held = ts.Simulator(middle)
    assert current.release_engines() == 1 and capacities() == [128]  # the Simulator's
    held.advance(0.002)
    assert held.ok.all()
    kept = held.engine.arena.nbytes  # capacity 128: twice the 64's
    ts.simulate(small, 0.002)  # used after the lease
    del held
    gc.collect()
    # room for the Simulator's engine alone: the other goes first, as used before it went
    assert current.release_engines(kept) == 1 and capacities() == [128]


@pytest.mark.slow  # suite time (5-8 s); test_reliability's thread tests stay in the default tier
def test_engines_are_destroyed_on_the_thread_that_started_taichi_alone(monkeypatch):
    """A call from another thread that reused an engine destroyed the others there, and every
    later build of the process failed on Taichi's assertion (a review, 2026-12): such a call
    leaves the engines for the next call on Taichi's thread, and `release_engines` from
    another thread is refused."""
    import threading

    current = runtime.Runtime.current()
    monkeypatch.setattr(current, "engines", {})
    robot = ts.StarParams(gait="A1", n_arc=6, n_limb=2)
    small, middle = [robot], [robot] * 65
    ts.simulate(small, 0.004)
    ts.simulate(middle, 0.004)
    monkeypatch.setattr(runtime, "FREE_ENGINES_BYTES", 0)
    outcome = {}

    def on_another_thread():
        outcome["summary"] = ts.simulate(small, 0.004).summary
        try:
            current.release_engines()
        except RuntimeError as error:
            outcome["refused"] = str(error)

    worker = threading.Thread(target=on_another_thread)
    worker.start()
    worker.join()
    assert (outcome["summary"]["status"] == "ok").all()
    assert outcome["refused"].startswith("release_engines must be called from the thread that "
                                         "started Taichi")
    assert sum(len(slots) for slots in current.engines.values()) == 2  # both kept there
    assert (ts.simulate(middle, 0.004).summary["status"] == "ok").all()
    # on this thread the budget of 0 keeps the engine in use alone
    assert [slot.engine.capacity for slots in current.engines.values() for slot in slots] == [128]


@pytest.mark.parametrize("lanes_by", [None, pytest.param("work", marks=pytest.mark.slow),
                                      pytest.param("batch", marks=pytest.mark.slow)])
def test_a_streamed_batchs_chunks_share_the_first_chunks_engine(monkeypatch, lanes_by):
    """129 robots in chunks of 65 and 64: the last chunk took an engine of its own (capacity 64
    beside 128), and with the kept engines bounded each call destroyed and built both again (a
    review, 2026-12). Every chunk now runs in the first one's engine: one build for two calls,
    the same bits as one engine. With lanes where the first chunk's work reaches their minimum
    and the last's does not, the last took one of its own too (lanes are part of an engine's
    key: a review), and so would it where the first chunk's size reaches the lanes' least
    batch and the last's does not (slow tier, the lanes' kernel compiles for ~7 s)."""
    current = runtime.Runtime.current()
    monkeypatch.setattr(current, "engines", {})
    robots = [ts.StarParams(gait=gait, n_arc=6, n_limb=2) for gait in ("A1", "A2", "A1+A3")] * 43
    whole = ts.simulate(robots, 0.004)
    probe = build_model(robots[:runtime.MIN_CAPACITY])
    per_instance = engine_bytes(probe, "f64") / runtime.batch_capacity(probe.batch_size)
    monkeypatch.setattr(runtime, "CPU_ENGINE_BUDGET_BYTES", 129 * per_instance)
    monkeypatch.setattr(runtime, "FREE_ENGINES_BYTES", 0)
    assert runtime.stream_chunk_size(robots, "f64", "cpu") == 65
    if lanes_by == "work":
        steps = 4  # 0.004 s at 1-ms steps
        monkeypatch.setattr(runtime, "LANES_MINIMUM_WORK", 65 * steps)
    elif lanes_by == "batch":
        monkeypatch.setattr(runtime, "LANES_MINIMUM_WORK", 0)
        monkeypatch.setattr(runtime, "LOCKSTEP_MINIMUM_BATCH", 65)
    built, kept_then = [], []
    new_engine = current.new_engine

    def counted(*args):
        built.append(args)
        kept_then.append(sum(len(slots) for slots in current.engines.values()))
        return new_engine(*args)

    monkeypatch.setattr(current, "new_engine", counted)
    for _ in range(2):
        streamed = ts.simulate(robots, 0.004)
        pd.testing.assert_frame_equal(streamed.summary, whole.summary, check_exact=True)
    assert len(built) == 1
    # the whole batch's engine went before the chunks' was built, not after (at a budget of 0
    # a process held both at once)
    assert kept_then == [0]



def test_a_streamed_batch_is_cut_into_parts_as_equal_as_whole_robots_allow(monkeypatch,
                                                                           simulated_chunks,
                                                                           capsys):
    """Chunks taken in steps of the chunk size left the rest to a last sliver (421 robots as 20
    chunks of 21 and one: a review, 2026-12): 43 robots at most 21 to a chunk run as 14, 14 and
    15, in one engine, the same bits as one call."""
    from taichi_star import simulation

    robots = [ts.StarParams(gait=gait, n_arc=6, n_limb=2) for gait in ("A1", "A2")] * 21
    robots.append(ts.StarParams(gait="A3", n_arc=6, n_limb=2))
    whole = ts.simulate(robots, 0.002)
    monkeypatch.setattr(simulation, "stream_chunk_size", lambda *args: 21)
    simulated_chunks.clear()  # the whole run's
    streamed = ts.simulate(robots, 0.002)
    assert [len(chunk) for chunk in simulated_chunks] == [14, 14, 15]
    pd.testing.assert_frame_equal(streamed.summary, whole.summary, check_exact=True)
    # each part's progress bar says which of how many it is, from two parts on
    monkeypatch.setattr(simulation, "stream_chunk_size", lambda *args: 1)
    capsys.readouterr()
    ts.simulate(robots[:2], 0.002, progress=True)
    bars = capsys.readouterr().err
    assert "1 robot, chunk 1/2:" in bars and "1 robot, chunk 2/2:" in bars


def test_a_sensitive_batch_is_streamed_by_its_instances_and_replicas(monkeypatch):
    """A sensitive batch asks for chunks by the instances each robot takes with its replicas
    (three with one direction), and its chunks' derivatives keep their robots' numbers: the
    same tables as one call (a mutation audit, 2026-12: neither was tested past
    `stream_chunk_size`)."""
    from taichi_star import simulation

    robots = [ts.StarParams(gait=gait, n_arc=6, n_limb=2) for gait in ("A1", "A3")]
    whole = ts.simulate(robots, 0.004, record_interval_s=0.002, sensitivities=["alpha"])
    asked = []
    monkeypatch.setattr(simulation, "stream_chunk_size",
                        lambda *args: asked.append(args[3]) or 1)  # a robot per chunk
    streamed = ts.simulate(robots, 0.004, record_interval_s=0.002, sensitivities=["alpha"])
    assert asked == [3]
    pd.testing.assert_frame_equal(streamed.sensitivities, whole.sensitivities, check_exact=True)
    pd.testing.assert_frame_equal(streamed.trajectory_sensitivities,
                                  whole.trajectory_sensitivities, check_exact=True)
    assert streamed.trajectory_sensitivities["instance"].tolist() == [0, 0, 0, 1, 1, 1]
