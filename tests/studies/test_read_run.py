"""`read_run`: a run store read back without the run's arguments gives what `run_batch` gave,
bit for bit, writes nothing, and refuses (or with partial=True leaves out, saying so) every
chunk it cannot trust; a folder that is not a run store is one line naming it."""

import errno
import json
import os
import warnings

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import taichi_star as ts
from taichi_star.batch import RunStoreError, read_run, run_batch
from taichi_star.batch import store as run_store

# dt 2 ms (not the default) so that the solver read back must come from the manifest
SOLVER = ts.SolverConfig(dt=2e-3)
# two topologies (n_arc 12 and 18) and three chunks of two: the read must put the instances
# back in input order across groups
PARAMS = [ts.StarParams(gait="A1+A3", alpha=0.6), ts.StarParams(gait="A1", n_arc=12),
          ts.StarParams(gait="A1+A2", alpha=1.0), ts.StarParams(gait="A1", n_arc=12, alpha=0.5),
          ts.StarParams(gait="A1+A4")]
TABLES = ("summary", "trajectory", "sensitivities", "trajectory_sensitivities")


def run(folder, params=PARAMS, solver=SOLVER, sensitivities=("alpha",)):
    return run_batch(params, 0.1, solver=solver, chunk_size=2, record_interval_s=0.05,
                     sensitivities=sensitivities, run_dir=folder)


@pytest.fixture(scope="module")
def stored(tmp_path_factory):
    """(run folder, run_batch's result) of a finished run with records and sensitivities."""
    folder = tmp_path_factory.mktemp("read_run") / "run"
    return folder, run(folder)


def copy_of(source, folder):
    folder.mkdir()
    for path in source.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    return folder


def contents(folder):
    return {path.name: path.read_bytes() for path in folder.iterdir()}


def test_a_finished_run_reads_back_as_run_batch_gave_it_and_nothing_is_written(stored,
                                                                               monkeypatch):
    folder, original = stored
    before = contents(folder)

    def no_writes(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))
    # read-only media: no file written, no lock file made
    monkeypatch.setattr(run_store, "write_atomic", no_writes)
    monkeypatch.setattr(run_store.os, "open", no_writes)
    back = read_run(folder)
    for table in TABLES:
        pd.testing.assert_frame_equal(getattr(back, table), getattr(original, table),
                                      check_exact=True)
    assert back.summary["instance"].tolist() == [0, 1, 2, 3, 4]
    assert back.solver == SOLVER and back.solver != ts.SolverConfig()
    assert back.arch == original.arch == "cpu"
    assert back.arguments == original.arguments
    assert back.code_versions is None  # made by this code
    assert back.timing.robot_steps == 0 and back.timing.run_s == 0.0
    assert repr(back).endswith("; nothing simulated by this call (its tables read back))")
    assert "nothing simulated" not in repr(original)  # its phases and rate
    assert back.topology is None  # two topologies, as run_batch's
    assert contents(folder) == before
    # the derivatives read back are the run's
    np.testing.assert_array_equal(back.sensitivity("signed_speed_mm_s", "alpha"),
                                  original.sensitivity("signed_speed_mm_s", "alpha"))


def test_a_run_of_one_topology_gets_its_topology_and_an_f32_run_its_own_tolerance(tmp_path):
    """A run in f32 left newton_tol to its default, its precision's own (1e-7 m), where the
    manifest's defaults record f64's (1e-10 m, which f32 refuses)."""
    solver = ts.SolverConfig(dt=2e-3, precision="f32")
    params = [ts.StarParams(gait="A1+A3"), ts.StarParams(gait="A1+A2", alpha=1.0)]
    # (sensitivities need f64)
    original = run(tmp_path / "run", params=params, solver=solver, sensitivities=())
    back = read_run(tmp_path / "run")
    assert back.solver == solver and back.solver.newton_tol == ts.NEWTON_TOL_DEFAULTS["f32"]
    np.testing.assert_array_equal(back.topology.edges, original.topology.edges)
    np.testing.assert_array_equal(back.topology.rest_positions, original.topology.rest_positions)
    pd.testing.assert_frame_equal(back.summary, original.summary, check_exact=True)


def manifest_of(folder):
    return json.loads((folder / "manifest.json").read_text())


def rewrite_manifest(folder, manifest):
    """Write `manifest` with a definition_sha256 that matches its definition (an edit a
    damaged-manifest check alone would not catch)."""
    manifest["definition_sha256"] = run_store._sha256(run_store._canonical(
        manifest["definition"]))
    (folder / "manifest.json").write_text(json.dumps(manifest))


def test_a_read_back_run_says_which_ok_instances_need_a_second_look(stored, tmp_path):
    """As run_batch does (a capped Newton solve, accepted after a retry)."""
    folder = copy_of(stored[0], tmp_path / "run")
    members, summary, trajectory = run_store.read_stored(folder).chunks[2]
    restamped(folder, {2: (members, summary.assign(newton_capped=[False, True]), trajectory)})
    with pytest.warns(RuntimeWarning, match=r"1 of 5 f64 instances \(the first: instance 3\) "
                                            r"are 'ok' only after"):
        read_run(folder)


def test_a_default_changed_since_the_run_is_read_as_the_run_had_it(stored, tmp_path):
    """The definition holds only what differs from the defaults of its day: a default
    recorded otherwise than today's is the run's setting (here an older max_newton)."""
    folder = copy_of(stored[0], tmp_path / "run")
    manifest = manifest_of(folder)
    manifest["defaults"]["solver"]["max_newton"] = 12
    rewrite_manifest(folder, manifest)
    # the chunks' stamps hold the definition's hash, which a defaults edit leaves alone
    back = read_run(folder)
    assert back.solver.max_newton == 12 and back.solver.dt == SOLVER.dt


def test_a_missing_chunk_is_refused_naming_it_and_partial_leaves_it_out_saying_so(stored,
                                                                                 tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    # the chunks are the groups in input order: n_arc 18 ([0, 2], [4]), then n_arc 12 ([1, 3])
    (folder / "chunk_000002.parquet").unlink()
    with pytest.raises(RunStoreError, match=r"1 of 3 chunks are not stored or not usable "
                                            r"\(chunk 2: not stored\).*resume=True"):
        read_run(folder)
    with pytest.warns(RuntimeWarning, match=r"1 of 3 chunks left out \(chunk 2: not stored\); "
                                            r"the result holds 3 of the run's 5 instances"):
        back = read_run(folder, partial=True)
    full = stored[1]
    # the others' rows, as they were
    kept = full.summary["instance"].isin([0, 2, 4])
    pd.testing.assert_frame_equal(back.summary, full.summary[kept].reset_index(drop=True),
                                  check_exact=True)
    kept_records = full.trajectory["instance"].isin([0, 2, 4])
    pd.testing.assert_frame_equal(back.trajectory,
                                  full.trajectory[kept_records].reset_index(drop=True),
                                  check_exact=True)
    assert back.topology is not None  # what is left shares one topology


def test_a_complete_run_reads_without_a_warning_even_with_partial(stored):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = read_run(stored[0], partial=True)
    assert len(back.summary) == len(PARAMS)


def test_a_damaged_chunk_is_named_and_left_as_it_is(stored, tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    path = folder / "chunk_000000.parquet"
    data = path.read_bytes()[:-100]   # cut short, as a full disk or a copy stopped leaves it
    path.write_bytes(data)
    with pytest.raises(RunStoreError, match=r"chunk 0: unreadable"):
        read_run(folder)
    assert path.read_bytes() == data  # a reader deletes nothing
    with pytest.warns(RuntimeWarning, match=r"1 of 3 chunks left out \(chunk 0: unreadable"):
        assert read_run(folder, partial=True).summary["instance"].tolist() == [1, 3, 4]


def test_a_chunk_whose_trajectory_is_gone_is_not_usable(stored, tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    (folder / "trajectory_000002.parquet").unlink()
    with pytest.raises(RunStoreError, match=r"chunk 2: its trajectory unreadable"):
        read_run(folder)


def test_no_usable_chunk_is_refused_even_with_partial(stored, tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    for path in folder.glob("chunk_*.parquet"):
        path.unlink()
    with pytest.raises(RunStoreError, match=r"none of its 3 chunks is stored and usable"):
        read_run(folder, partial=True)


def test_chunks_of_a_definition_edited_since_are_another_runs(stored, tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    manifest = manifest_of(folder)
    manifest["definition"]["duration_s"] = 0.2
    rewrite_manifest(folder, manifest)
    # the chunks' stamps name the old definition's hash
    with pytest.raises(RunStoreError, match=r"3 of 3 chunks.*from another run"):
        read_run(folder)


def restamped(folder, chunks, **definition_changes):
    """Rewrite the run in `folder`: its definition with `definition_changes`, and `chunks`
    (index → (members, summary, trajectory)) stamped for it, as a store of that definition
    writes them (a run's own hash on chunks that hold something else)."""
    manifest = manifest_of(folder)
    manifest["definition"].update(definition_changes)
    rewrite_manifest(folder, manifest)
    store = run_store.RunStore(folder, manifest["definition"])
    for index, (members, summary, trajectory) in chunks.items():
        store.write(run_store.StoredChunk(index, members, 0.05), summary, trajectory)


def test_chunks_whose_instances_are_not_the_recorded_plan_are_refused(stored, tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    chunks = run_store.read_stored(folder).chunks
    restamped(folder, chunks, chunks_sha256="0" * 64)
    for partial in (False, True):  # every chunk is there: nothing to leave out
        with pytest.raises(RunStoreError, match=r"its chunks' instances are not the chunk plan"):
            read_run(folder, partial=partial)


@pytest.mark.parametrize("instance", [0, 5])   # another chunk's; past the run's 5
def test_a_chunk_holding_an_instance_not_its_own_is_refused(stored, tmp_path, instance):
    folder = copy_of(stored[0], tmp_path / "run")
    chunks = run_store.read_stored(folder).chunks
    members, summary, trajectory = chunks[0]
    first = summary["instance"] == 0
    restamped(folder, {1: ((instance,), summary[first].assign(instance=instance),
                           trajectory[trajectory["instance"] == 0].assign(instance=instance))})
    with pytest.raises(RunStoreError, match=rf"chunk_000001.parquet holds instance {instance}, "
                                            rf"which is not one of its run's or is another "
                                            rf"chunk's"):
        read_run(folder, partial=True)


def test_a_chunk_whose_table_holds_other_instances_than_its_stamp_is_not_usable(stored,
                                                                                 tmp_path):
    folder = copy_of(stored[0], tmp_path / "run")
    chunks = run_store.read_stored(folder).chunks
    members, summary, trajectory = chunks[0]
    first = summary["instance"] == 0
    restamped(folder, {1: ((4,), summary[first], trajectory[trajectory["instance"] == 0])})
    with pytest.raises(RunStoreError, match=r"chunk 1: its table holds other instances than "
                                            r"its stamp names"):
        read_run(folder)


@pytest.mark.parametrize("key, value", [("n_chunks", "3"), ("n_chunks", None),
                                        ("arch", 0), ("n_instances", True)])
def test_a_definition_missing_what_reading_needs_is_named(stored, tmp_path, key, value):
    folder = copy_of(stored[0], tmp_path / "run")
    manifest = manifest_of(folder)
    manifest["definition"][key] = value
    rewrite_manifest(folder, manifest)
    with pytest.raises(RunStoreError, match=rf"manifest.json is damaged \(its definition's "
                                            rf"{key} is {value!r}\)"):
        read_run(folder)


def test_what_is_not_a_run_store_is_one_line_naming_it(tmp_path):
    with pytest.raises(RunStoreError, match=r"run_dir .*nowhere: no such folder"):
        read_run(tmp_path / "nowhere")
    (tmp_path / "a_file").write_text("x")
    with pytest.raises(RunStoreError, match=r"a_file: is not a folder"):
        read_run(tmp_path / "a_file")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RunStoreError, match=r"--run-dir .*empty: has no manifest.json"):
        read_run(tmp_path / "empty", run_dir_flag="--run-dir")
    with pytest.raises(ValueError, match=r"run_dir must be the path of the run store's folder"):
        read_run("")
    with pytest.raises(ValueError, match=r"partial must be True or False, got 'yes'"):
        read_run(tmp_path / "empty", partial="yes")


@settings(max_examples=20, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(gone=st.sets(st.integers(0, 2), max_size=2))
def test_any_chunks_gone_leave_exactly_the_others_rows(stored, tmp_path_factory, gone):
    """Whichever chunks are missing (none to all but one), partial=True gives the other
    chunks' instances, their rows as the whole run's, in input order, and the count said."""
    folder = copy_of(stored[0], tmp_path_factory.mktemp("gone") / "run")
    members = {index: chunk[0] for index, chunk in run_store.read_stored(folder).chunks.items()}
    for index in gone:
        (folder / f"chunk_{index:06d}.parquet").unlink()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        back = read_run(folder, partial=True)
    kept = sorted(m for index, chunk in members.items() if index not in gone for m in chunk)
    full = stored[1]
    for table in ("summary", "sensitivities"):
        rows = getattr(full, table)[full.summary["instance"].isin(kept)].reset_index(drop=True)
        pd.testing.assert_frame_equal(getattr(back, table), rows, check_exact=True)
    said = [str(w.message) for w in caught if "left out" in str(w.message)]
    assert len(said) == (1 if gone else 0)
    if gone:
        assert f"the result holds {len(kept)} of the run's 5 instances" in said[0]
