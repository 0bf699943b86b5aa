"""The host code around a run (`simulate`, `SimulationResult`, the field arena and store, a
state's checks): refusals before any compute, what a result's repr, timing and arch say, the
warnings about 'ok' instances, a streamed batch's numbering, a failed robot's NaN heading, and
what a damaged snapshot may not hold. Found by a mutation audit (2026-12-07): each test kills
a change of the code that the suite let live."""

import dataclasses
import re
import time
import warnings

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star import runtime, simulation
from taichi_star.simulation import SimulationResult, warn_about_ok_instances

SMALL = ts.StarParams(n_arc=6, n_limb=2)


class ComputeStarted(Exception):
    pass


@pytest.fixture
def no_compute(monkeypatch):
    def refuse(*args, **kwargs):
        raise ComputeStarted
    monkeypatch.setattr(runtime.Runtime, "ensure", refuse)


@pytest.mark.parametrize("keywords, message", [
    (dict(solver="f64"), r"^solver must be a SolverConfig, got str"),
    (dict(record_shapes=True), r"^record_shapes needs record_interval_s > 0"),
    (dict(steady_from_cycle=-1), r"^steady_from_cycle must be an integer >= 0, got -1"),
    (dict(steady_from_cycle=1.5), r"^steady_from_cycle must be an integer >= 0, got 1.5"),
])
def test_simulate_refuses_a_bad_solver_shapes_without_records_and_a_bad_steady_cycle(
        no_compute, keywords, message):
    """A solver given as text, shapes asked without records, a steady window from cycle -1 or
    1.5: each refused by name before any compute (without its check: an AttributeError, no
    shapes, no error)."""
    with pytest.raises(ValueError, match=message):
        ts.simulate([SMALL], 0.002, **keywords)


def hand_made_result(**fields):
    """A SimulationResult of two instances recorded at 0, 0.1 and 0.2 s, without sensitivities."""
    summary = pd.DataFrame({"status": ["ok", "ok"]})
    trajectory = pd.DataFrame({"instance": [0, 0, 0, 1, 1, 1], "t_s": [0.0, 0.1, 0.2] * 2,
                               "x_mm": 0.0, "y_mm": 0.0, "heading_deg": 0.0})
    return SimulationResult(summary=summary, trajectory=trajectory, shapes=None, topology=None,
                            solver=ts.SolverConfig(), **fields)


def test_a_results_repr_counts_its_record_times_and_sensitivity_needs_sensitivities():
    """The repr counts record times (3), not rows (6: two instances); a result without
    sensitivities says so when asked for one."""
    result = hand_made_result()
    assert "3 records" in repr(result)
    with pytest.raises(ValueError, match=r"^this result has no sensitivities"):
        result.sensitivity("speed_mm_s", "alpha")


def summary_of(status, capped, sane, instance=None):
    """A summary's columns that `warn_about_ok_instances` reads, max_strain 0.01, 0.02, ...;
    with `instance`, a filtered batch's instance column."""
    table = pd.DataFrame({"status": status, "newton_capped": capped, "shape_sane": sane,
                          "max_strain": [0.01 * (k + 1) for k in range(len(status))]})
    if instance is not None:
        table.insert(0, "instance", instance)
    return table


def test_only_ok_instances_are_warned_about_naming_them_by_their_instance_column():
    """A failed instance is not warned about as 'ok'; the first of a filtered summary is named
    by its instance column (7), not its row."""
    # a failed instance's Newton solve used all its iterations and it has no sane shape: no
    # 'ok' warning for it
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warn_about_ok_instances(summary_of(["newton_failed"], [True], [False]),
                                ts.SolverConfig())
    # rows of a batch's summary (a filtered one): the first named by its instance column
    with pytest.warns(RuntimeWarning, match=r"1 of 2 f64 instances \(the first: instance 7\)"):
        warn_about_ok_instances(summary_of(["ok", "ok"], [False, True], [True, True], [5, 7]),
                                ts.SolverConfig())


def test_an_unstreamed_run_s_progress_bar_names_no_chunk(capsys):
    """A batch run in one chunk says so in no bar ("chunk 1/1" read as streaming)."""
    capsys.readouterr()
    ts.simulate([SMALL], 0.002, progress=True)
    bars = capsys.readouterr().err
    assert "1 robot" in bars and "chunk" not in bars


def test_a_result_records_its_arch_and_its_setup_counts_taichi_s_start(monkeypatch):
    """`result.arch` is the arch it ran on, and `timing.setup_s` counts Taichi's start (made
    to take 0.3 s here)."""
    ts.simulate([SMALL], 0.002)  # its engine built and kept: the next call's setup is short
    ensure, calls = runtime.Runtime.ensure, []

    def slow(self, *args):  # Taichi's start (simulate's first call) takes 0.3 s
        if not calls:
            time.sleep(0.3)
        calls.append(args)
        return ensure(self, *args)

    monkeypatch.setattr(runtime.Runtime, "ensure", slow)
    result = ts.simulate([SMALL], 0.002)
    assert result.arch == "cpu"
    assert result.timing.setup_s >= 0.3


def test_a_batch_streamed_in_unequal_chunks_numbers_its_records_and_counts_all_its_work(
        monkeypatch):
    """Chunks of 1 and 2 robots number their records as the whole batch does (the offsets
    from every earlier chunk) and count every chunk's steps in the timing."""
    robots = [ts.StarParams(gait=gait, n_arc=6, n_limb=2) for gait in ("A1", "A2", "A3")]
    whole = ts.simulate(robots, 0.004, record_interval_s=0.002)
    monkeypatch.setattr(simulation, "stream_chunk_size", lambda *args: 2)  # chunks of 1 and 2
    streamed = ts.simulate(robots, 0.004, record_interval_s=0.002)
    pd.testing.assert_frame_equal(streamed.trajectory, whole.trajectory, check_exact=True)
    assert streamed.timing.robot_steps == whole.timing.robot_steps == 3 * 4


def test_the_unphysical_warning_gives_the_largest_strain_of_its_instances():
    """The warning about 'ok' instances of unphysical shapes gives the largest strain among
    them (0.03), not the smallest."""
    with pytest.warns(RuntimeWarning, match=r"2 of 3 'ok' instances \(the first: instance 1\) "
                                            r".*max_strain up to 0\.03\)"):
        warn_about_ok_instances(summary_of(["ok", "ok", "ok"], [False] * 3,
                                           [True, False, False]), ts.SolverConfig())


def test_the_chords_newton_iterations_are_not_its_factorisations():
    """A chord run factors once a step while its Newton solves take more than one update: the
    iterations' mean is not the factorisations'."""
    summary = ts.simulate([ts.StarParams(gait="A1+A2", n_arc=6, n_limb=2)], 0.02,
                          ts.SolverConfig(jacobian="chord")).summary
    assert summary["factorisations_mean"].iloc[0] == 1.0
    assert summary["newton_iterations_mean"].iloc[0] > 1.5


def test_a_failed_instances_heading_is_nan_in_its_summary_and_records():
    """A failed robot's heading is NaN in its summary and in its records from its failure on
    (positions and heading alike), its records before the failure kept."""
    solver = ts.SolverConfig(dt=0.05, max_newton=3, max_substep_halvings=0)
    robots = [ts.StarParams(gait="A1+A2", youngs_modulus=1e10, limb_stiffness_ratio=1e4),
              ts.StarParams(gait="none")]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        result = ts.simulate(robots, 0.1, solver, record_interval_s=0.05)
    summary = result.summary
    assert summary["status"].tolist() == ["newton_failed", "ok"]
    assert np.isnan(summary["heading_deg"].iloc[0]) and summary["heading_deg"].iloc[1] == 0.0
    failed = result.trajectory[result.trajectory["instance"] == 0]
    after = failed["t_s"] >= summary["failure_time_s"].iloc[0]
    assert after.any() and failed.loc[after, ["x_mm", "y_mm", "heading_deg"]].isna().all().all()
    assert failed.loc[~after, ["x_mm", "y_mm", "heading_deg"]].notna().all().all()


def test_a_store_of_floats_alone_round_trips_and_a_misshapen_entry_is_refused(taichi_cpu):
    """A FieldStore of float fields alone round-trips; a transposed entry of the same size and a
    missing field are refused by name, the stored values unchanged."""
    from taichi_star.fields import FieldArena, FieldStore

    arena = FieldArena()
    fields = {"a": arena.batch_field(float, (2, 3)), "b": arena.batch_field(float, 4)}
    arena.finalize()
    store = FieldStore(fields)  # no integer field: an empty int64 array to pack
    values = {"a": np.arange(6.0).reshape(2, 3), "b": np.array([0.5, -1.0, 2.0, 3.0])}
    store.write(values)
    back = store.read()
    assert all(np.array_equal(back[name], values[name]) for name in values)
    # the same number of values in another shape (transposed) is refused, not written
    with pytest.raises(ValueError, match=r"^field 'a' has shape \(2, 3\), got \(3, 2\)"):
        store.write({**values, "a": np.zeros((3, 2))})
    with pytest.raises(ValueError, match=r"^no values for field 'b'"):
        store.write({"a": values["a"]})
    assert np.array_equal(store.read()["a"], values["a"])


def test_a_snapshot_field_of_another_shape_is_refused_naming_it(taichi_cpu):
    """A snapshot field cut short is refused naming it (without the shape check, pending_due
    gave an IndexError)."""
    sim = ts.Simulator([ts.StarParams(gait="none", n_arc=6, n_limb=2)], ts.SolverConfig())
    saved = sim.save()
    for name in ("positions", "pending_due"):
        fields = {**saved.fields, name: saved.fields[name][:, :-1]}
        with pytest.raises(ValueError, match=rf"^saved state field '{name}' has shape"):
            sim.load(dataclasses.replace(saved, fields=fields))


def test_an_arena_destroyed_twice_gives_its_tree_back_once(taichi_cpu):
    """A second `destroy` of a field arena is a no-op, not a failure."""
    from taichi_star.fields import FieldArena

    arena = FieldArena()
    arena.batch_field(float, (2, 3))
    arena.finalize()
    arena.destroy()
    assert arena.tree is None
    arena.destroy()


@pytest.mark.parametrize("values, reason", [
    ({"history_valid": 2}, "'history_valid' holds a value other than 0 or 1"),
    ({"pending_count": 1, "pending_actuators": 0},
     "'pending_actuators' holds 0, not a set of actuators in [1, 255]"),
])
def test_a_history_flag_of_2_and_a_firing_of_no_actuator_are_refused(taichi_cpu, values, reason):
    """A damaged snapshot's BDF2 history flag of 2, or a pending firing of no actuator, is
    refused by `check_saved_values`, naming the field."""
    from taichi_star.state import check_saved_values

    fields = {name: array.copy() for name, array in
              ts.Simulator([ts.StarParams(gait="none", n_arc=6, n_limb=2)]).save().fields.items()}
    for name, value in values.items():
        fields[name][0] = value
    with pytest.raises(ValueError, match=re.escape(f"saved state field {reason} (a damaged")):
        check_saved_values(fields)


def test_a_fresh_state_marks_every_padding_row_inactive(taichi_cpu):
    """Every padding row of a fresh state is inactive from the first one past the batch (one
    marked ok would be simulated for nothing)."""
    from taichi_star.state import STATUS_INACTIVE, STATUS_OK

    fields = ts.Simulator([ts.StarParams(gait="none", n_arc=6, n_limb=2)] * 2).save().fields
    capacity = len(fields["status"])
    assert capacity > 2
    assert fields["status"].tolist() == [STATUS_OK] * 2 + [STATUS_INACTIVE] * (capacity - 2)
