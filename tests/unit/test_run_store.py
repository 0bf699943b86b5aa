"""The run store without simulations: chunk summaries built by hand as small tables, so every
rule of the store (what a run's definition is, what makes a chunk file trusted, when a folder is
refused, what the manifest records) is checked in milliseconds."""

import errno
import hashlib
import json
import logging
import os
import re
import shutil
import subprocess
import threading
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import taichi_star as ts
from taichi_star import provenance
from taichi_star.actuation import CurvatureProfile
from taichi_star.batch import store as run_store
from taichi_star.batch.store import (LOCK, RunStore, RunStoreError, definition_differences,
                                     run_definition, stored_chunk_size, table_checksum)
from taichi_star.batch.tasks import plan_chunks

SOLVER = ts.SolverConfig(dt=2e-3)
PARAMS = [ts.StarParams(gait=g, alpha=a) for g in ("A1", "A1+A3") for a in (0.4, 0.8)]
CHUNK = 3  # two chunks: 3 + 1 instances


def tasks_of(params=PARAMS, chunk_size=CHUNK, **kwargs):
    return plan_chunks(params, kwargs.pop("duration_s", 0.1), chunk_size=chunk_size,
                       solver=kwargs.pop("solver", SOLVER), **kwargs)


def definition_of(params=PARAMS, chunk_size=CHUNK, duration_s=0.1, **kwargs):
    return run_definition(params, tasks_of(params, chunk_size, duration_s=duration_s, **kwargs),
                          chunk_size, None, duration_s)


def summary_of(task):
    """A chunk summary shaped like run_chunk's: instance, a gait text, a value object, numbers
    whose last bits matter, a bool and an int column."""
    n = len(task.members)
    return pd.DataFrame({
        "instance": np.asarray(task.members, dtype=np.int64),
        "gait": [p.gait for p in task.params],
        "actuator_profile": pd.Series([p.actuator_profile for p in task.params], dtype=object),
        "speed_mm_s": np.array([1.0 / 3.0 + k for k in range(n)]) * (task.index + 1),
        "converged": np.arange(n) % 2 == 0,
        "newton_iterations": np.arange(n, dtype=np.int32) + 7,
    })


def store_in(path, params=PARAMS):
    return RunStore(path, definition_of(params))


def manifest_of(folder):
    return json.loads((Path(folder) / "manifest.json").read_text())


def set_manifest(folder, **changes):
    manifest = manifest_of(folder)
    manifest.update(changes)
    (Path(folder) / "manifest.json").write_text(json.dumps(manifest))


@pytest.fixture
def written(tmp_path):
    """(folder, tasks) of a run whose two chunks are written, not yet finished."""
    folder = tmp_path / "run"
    tasks = tasks_of()
    store = store_in(folder)
    assert store.open(tasks, resume=False) == []
    for task in tasks:
        store.write(task, summary_of(task))
    return folder, tasks


# --- the definition ---

def test_definition_records_what_a_resumed_run_must_repeat():
    tasks = tasks_of(record_interval_s=0.02, steady_from_cycle=2)
    definition = run_definition(PARAMS, tasks, CHUNK, None, 0.1)
    assert definition["format"] == 3
    assert definition["n_instances"] == 4 and definition["n_chunks"] == 2
    assert definition["chunk_size"] == CHUNK and type(definition["chunk_size"]) is int
    assert definition["cycles"] is None
    assert definition["duration_s"] == 0.1 and type(definition["duration_s"]) is float
    # the settings and parameters that differ from their defaults, so that a field added
    # later with a default that changes nothing keeps a run resumable (an audit, 2026-12)
    assert definition["solver"] == {"dt": 2e-3}
    # (A1, 0.4), (A1, 0.8), (A1+A3, 0.4), (A1+A3, 0.8) against the defaults A1 and α = 0.8
    changes = [{"alpha": 0.4}, {}, {"alpha": 0.4, "gait": "A1+A3"}, {"gait": "A1+A3"}]
    assert definition["params_sha256"] == hashlib.sha256("\n".join(
        json.dumps(change, sort_keys=True, separators=(",", ":")) for change in changes
    ).encode()).hexdigest()
    assert definition["arch"] == "cpu"
    assert definition["record_interval_s"] == 0.02 and definition["steady_from_cycle"] == 2
    assert json.loads(json.dumps(definition)) == definition  # JSON-ready
    by_cycles = run_definition(PARAMS, tasks, CHUNK, 2, None)
    assert by_cycles["cycles"] == 2.0 and type(by_cycles["cycles"]) is float
    assert by_cycles["duration_s"] is None


def test_definition_hashes_change_with_the_parameters_and_the_chunk_plan_only():
    base = definition_of()
    assert definition_of() == base
    assert definition_of([p.replace(alpha=p.alpha + 1e-12) for p in PARAMS])["params_sha256"] \
        != base["params_sha256"]
    assert definition_of(PARAMS[::-1])["params_sha256"] != base["params_sha256"]
    # another cut of the same instances: same parameters, other chunks
    other_cut = definition_of(chunk_size=2)
    assert other_cut["params_sha256"] == base["params_sha256"]
    assert other_cut["chunks_sha256"] != base["chunks_sha256"]
    assert len(base["params_sha256"]) == len(base["chunks_sha256"]) == 64


def test_definition_differences_name_each_changed_field():
    old = definition_of()
    new = definition_of(solver=SOLVER.replace(dt=1e-3, max_newton=30), chunk_size=2)
    assert definition_differences(old, old) == []
    assert definition_differences(old, new) == [
        "chunk_size: 3 -> 2", f"chunks_sha256: {old['chunks_sha256']!r} -> "
        f"{new['chunks_sha256']!r}", "solver.dt: 0.002 -> 0.001", "solver.max_newton: 25 -> 30"]
    fewer = definition_differences(old, definition_of(PARAMS[:3]))
    assert "n_chunks: 2 -> 1" in fewer and "n_instances: 4 -> 3" in fewer
    assert "the instance parameters differ" in definition_differences(old, definition_of(
        [p.replace(cylinder_drag=20.0) for p in PARAMS]))
    assert definition_differences({"a": 1}, {"b": {"c": 2}}) == ["a: 1 -> None",
                                                                "b: None -> {'c': 2}"]
    assert definition_differences({"s": {"x": 1}}, {"s": {"y": 1}}) == ["s.x: 1 -> None",
                                                                        "s.y: None -> 1"]


# --- the checksum ---

def test_checksum_sees_every_bit_name_dtype_and_text():
    frame = summary_of(tasks_of()[0]).drop(columns="actuator_profile")
    reference = table_checksum(frame)
    assert table_checksum(frame.copy()) == reference and len(reference) == 64
    changed = {
        "last bit": frame.assign(speed_mm_s=np.nextafter(frame["speed_mm_s"], np.inf)),
        "name": frame.rename(columns={"speed_mm_s": "speed"}),
        "order": frame[frame.columns[::-1]],
        "dtype": frame.assign(newton_iterations=frame["newton_iterations"].astype(np.int64)),
        "text": frame.assign(gait=["A1", "A1", "A1+A4"]),
        "bool": frame.assign(converged=~frame["converged"]),
        "missing text": frame.assign(gait=["A1", "A1", None]),
    }
    for what, other in changed.items():
        assert table_checksum(other) != reference, what
    # the same bytes under another numeric dtype (0.0 and 0 are both eight zero bytes)
    zeros = pd.DataFrame({"x": np.zeros(3)})
    assert table_checksum(zeros) != table_checksum(zeros.astype(np.int64))


def test_checksum_of_text_treats_every_missing_value_alike():
    with_none = pd.DataFrame({"status": ["ok", None]})
    with_nan = pd.DataFrame({"status": ["ok", np.nan]})
    assert table_checksum(with_none) == table_checksum(with_nan)
    assert table_checksum(with_none) != table_checksum(pd.DataFrame({"status": ["ok", "None"]}))
    assert table_checksum(with_none) != table_checksum(pd.DataFrame({"status": ["ok", "nan"]}))


# --- chunks ---

def test_chunk_round_trip_keeps_every_bit_dtype_and_value_object(written):
    folder, tasks = written
    store = store_in(folder)
    for task in tasks:
        expected = summary_of(task)
        stored = store.read(task)
        pd.testing.assert_frame_equal(stored, expected, check_exact=True)
        assert isinstance(stored["actuator_profile"].iloc[0], CurvatureProfile)
    assert store.chunk_path(1) == folder / "chunk_000001.parquet"
    # and the lock of the run that wrote them, which has not ended (`LOCK`, hidden)
    assert sorted(p.name for p in folder.iterdir()) == [
        LOCK, "chunk_000000.parquet", "chunk_000001.parquet", "manifest.json"]


def test_a_chunk_without_value_objects_or_rows_round_trips(tmp_path):
    store = store_in(tmp_path / "run")
    tasks = tasks_of()
    store.open(tasks, resume=False)
    plain = summary_of(tasks[0]).drop(columns="actuator_profile")
    store.write(tasks[0], plain)
    pd.testing.assert_frame_equal(store.read(tasks[0]), plain, check_exact=True)
    empty = plain.iloc[:0]
    store.write(tasks[1], empty)
    assert len(store.read(tasks[1])) == 0
    # a column with no value in any row (object dtype, all None) is not a value-object column
    blank = plain.assign(note=pd.Series([None] * len(plain), dtype=object))
    store.write(tasks[0], blank)
    assert store.read(tasks[0])["note"].isna().all()


def test_a_column_of_python_strings_reads_back_and_verifies(tmp_path):
    """Text kept as Python objects (object dtype) comes back from Parquet as pandas' string
    dtype: the chunk still verifies and its values are the same strings."""
    store = store_in(tmp_path / "run")
    tasks = tasks_of()
    store.open(tasks, resume=False)
    plain = summary_of(tasks[0]).drop(columns="actuator_profile")
    notes = ["first", "second", None]
    store.write(tasks[0], plain.assign(note=pd.Series(notes, dtype=object)))
    back = store.read(tasks[0])
    assert [None if pd.isna(v) else v for v in back["note"]] == notes
    pd.testing.assert_frame_equal(back.drop(columns="note"), plain, check_exact=True)


def test_a_chunk_file_holds_the_rows_not_the_index(tmp_path):
    """A summary cut from a larger table is stored as its rows: read back numbered from 0, the
    file's columns are the summary's (no index column for other Parquet readers)."""
    store = store_in(tmp_path / "run")
    tasks = tasks_of()
    store.open(tasks, resume=False)
    summary = summary_of(tasks[0])
    cut = summary.set_axis([7, 3, 5])
    path = store.write(tasks[0], cut)
    assert pq.read_table(path).column_names == list(summary.columns)
    pd.testing.assert_frame_equal(store.read(tasks[0]), summary, check_exact=True)


def test_the_chunk_stamp_names_run_chunk_members_and_checksum(written):
    folder, tasks = written
    metadata = pq.read_table(folder / "chunk_000001.parquet").schema.metadata
    stamp = json.loads(metadata[b"taichi_star.chunk"])
    assert stamp["definition_sha256"] == store_in(folder).definition_sha256
    assert stamp["chunk"] == 1 and stamp["members"] == [3]
    assert stamp["value_types"] == {"actuator_profile": "CurvatureProfile"}
    assert manifest_of(folder)["definition_sha256"] == stamp["definition_sha256"]


def rewrite(path, frame=None, stamp_changes=None, drop_stamp=False):
    """Rewrite a chunk file with another table and/or stamp."""
    table = pq.read_table(path)
    metadata = dict(table.schema.metadata)
    stamp = json.loads(metadata[b"taichi_star.chunk"])
    stamp.update(stamp_changes or {})
    metadata[b"taichi_star.chunk"] = json.dumps(stamp).encode()
    if drop_stamp:
        del metadata[b"taichi_star.chunk"]
    if frame is not None:
        table = pa.Table.from_pandas(frame, preserve_index=False)
    pq.write_table(table.replace_schema_metadata(metadata), path)


@pytest.mark.parametrize("damage,reason", [
    (lambda path: path.write_bytes(path.read_bytes()[:100]),
     r"unreadable \(Could not open Parquet input source .*magic bytes not found.*\)"),
    (lambda path: path.write_bytes(b""),
     r"unreadable \(Could not open Parquet input source .*file size is 0 bytes\)"),
    (lambda path: rewrite(path, drop_stamp=True), r"no taichi_star chunk metadata"),
    (lambda path: rewrite(path, stamp_changes={"definition_sha256": "0" * 64}),
     r"from another run \(its definition differs\)"),
    (lambda path: rewrite(path, stamp_changes={"chunk": 1}), r"holds another chunk's instances"),
    (lambda path: rewrite(path, stamp_changes={"members": [0, 1, 3]}),
     r"holds another chunk's instances"),
    (lambda path: rewrite(path, frame=pq.read_table(path).to_pandas().assign(
        speed_mm_s=lambda f: np.nextafter(f["speed_mm_s"], 0))),
     r"its content does not match its checksum"),
])
def test_a_damaged_chunk_is_reported_deleted_and_not_counted_as_done(written, damage, reason,
                                                                     caplog):
    folder, tasks = written
    path = folder / "chunk_000000.parquet"
    damage(path)
    with pytest.raises(RunStoreError) as error:
        store_in(folder).read(tasks[0])
    assert re.fullmatch(f"{re.escape(str(path))}: {reason}", str(error.value))
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        done = store_in(folder).open(tasks, resume=True)
    assert done == [1]
    assert not path.exists() and (folder / "chunk_000001.parquet").exists()
    [warning] = [r.getMessage() for r in caplog.records]
    assert re.fullmatch(f"{re.escape(str(path))}: {reason}; recomputing it", warning)


@pytest.mark.parametrize("name", ["chunk_000001.parquet", "trajectory_000000.parquet",
                                  "manifest.json"])
@pytest.mark.parametrize("resume", [True, False])
def test_a_folder_in_place_of_a_stores_file_is_refused_naming_it(written, name, resume):
    """A folder where the store keeps a file can be neither read, replaced nor deleted by it
    (an IsADirectoryError from deep inside before): refused before the run, naming it, and
    left as it is."""
    folder, tasks = written
    path = folder / name
    path.unlink(missing_ok=True)
    (path / "inside").mkdir(parents=True)
    with pytest.raises(RunStoreError, match=re.escape(
            f"run_dir {folder}: {name} is not a file; remove it or choose another run_dir")):
        store_in(folder).open(tasks, resume=resume)
    assert (path / "inside").is_dir() and (folder / "chunk_000000.parquet").is_file()


def test_a_chunk_stamp_without_value_types_reads_plain_columns(tmp_path):
    """value_types may be absent from a stamp (a chunk without value-object columns)."""
    store = store_in(tmp_path / "run")
    tasks = tasks_of()
    store.open(tasks, resume=False)
    plain = summary_of(tasks[0]).drop(columns="actuator_profile")
    path = store.write(tasks[0], plain)
    table = pq.read_table(path)
    metadata = dict(table.schema.metadata)
    stamp = json.loads(metadata[b"taichi_star.chunk"])
    del stamp["value_types"]
    metadata[b"taichi_star.chunk"] = json.dumps(stamp).encode()
    pq.write_table(table.replace_schema_metadata(metadata), path)
    pd.testing.assert_frame_equal(store.read(tasks[0]), plain, check_exact=True)


def test_a_chunk_never_written_is_not_counted_as_done(written):
    folder, tasks = written
    (folder / "chunk_000000.parquet").unlink()
    assert store_in(folder).open(tasks, resume=True) == [1]


def test_a_chunk_of_another_definition_is_refused(written, tmp_path):
    """Two runs of other parameters cut the same way write the same chunk stamps but for their
    definition's hash, which alone tells their chunks apart."""
    folder, tasks = written
    other = RunStore(tmp_path / "other", definition_of([p.replace(alpha=1.5) for p in PARAMS]))
    assert other.definition_sha256 != store_in(folder).definition_sha256
    (tmp_path / "other").mkdir()
    shutil.copy(folder / "chunk_000000.parquet", tmp_path / "other")
    with pytest.raises(RunStoreError, match=r"from another run \(its definition differs\)"):
        other.read(tasks[0])


def test_a_definition_hash_does_not_depend_on_the_order_of_its_keys(tmp_path):
    definition = definition_of()
    reordered = dict(reversed(list(definition.items())))
    reordered["solver"] = dict(reversed(list(definition["solver"].items())))
    assert list(reordered) != list(definition)
    assert RunStore(tmp_path, reordered).definition_sha256 == \
        RunStore(tmp_path, definition).definition_sha256


# --- opening a folder ---

def test_a_fresh_run_writes_an_unfinished_manifest(tmp_path):
    folder = tmp_path / "deep" / "run"
    store = store_in(folder)
    assert store.open(tasks_of(), resume=False) == []
    manifest = manifest_of(folder)
    assert manifest["definition"] == definition_of()
    assert manifest["complete"] is False and "finished" not in manifest
    assert manifest["code"]["version"] == ts.__version__
    assert "resumed" not in manifest and manifest["created"]
    store.finish()
    manifest = manifest_of(folder)
    assert manifest["complete"] is True and manifest["finished"] >= manifest["created"]
    assert [p.name for p in folder.iterdir()] == ["manifest.json"]  # no temporary left
    # written for people too: one key a line, indented, in sorted order
    text = (folder / "manifest.json").read_text()
    assert text == json.dumps(manifest, indent=2, sort_keys=True)


def test_a_manifest_without_its_creation_time_gets_the_resumption_time(written):
    folder, tasks = written
    manifest = manifest_of(folder)
    del manifest["created"]
    (folder / "manifest.json").write_text(json.dumps(manifest))
    store_in(folder).open(tasks, resume=True)
    manifest = manifest_of(folder)
    assert manifest["created"] == manifest["resumed"][-1] and manifest["created"] > "2000"


def test_resuming_keeps_the_creation_time_and_lists_each_resumption(written):
    folder, tasks = written
    set_manifest(folder, created="2000-01-01T00:00:00", resumed=["2000-01-02T00:00:00"])
    assert store_in(folder).open(tasks, resume=True) == [0, 1]
    manifest = manifest_of(folder)
    assert manifest["created"] == "2000-01-01T00:00:00"
    assert manifest["resumed"][0] == "2000-01-02T00:00:00" and len(manifest["resumed"]) == 2
    assert manifest["resumed"][1] > "2000"
    assert manifest["complete"] is False


OLD_CODE = {"version": "0.0.1", "commit": "abc", "dirty": False}


def test_resuming_a_run_of_other_code_warns_naming_both(written):
    """Allowed (a typo fixed), but a RuntimeWarning to the user (a log line before)."""
    folder, tasks = written
    set_manifest(folder, code=OLD_CODE, code_versions=[{"code": OLD_CODE, "chunks": [0, 1]}])
    with pytest.warns(RuntimeWarning) as warned:
        assert store_in(folder).open(tasks, resume=True) == [0, 1]
    assert [str(w.message) for w in warned] == [
        f"resuming a run started with code {OLD_CODE}; now {run_store.code_version()}: the "
        f"manifest's code_versions records which chunks each made"]


def test_resuming_the_same_code_does_not_warn(written, caplog):
    folder, tasks = written
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"), warnings.catch_warnings():
        warnings.simplefilter("error")
        assert store_in(folder).open(tasks, resume=True) == [0, 1]
    assert caplog.text == ""
    assert manifest_of(folder)["code_versions"] == [{"code": run_store.code_version(),
                                                     "chunks": [0, 1]}]


def test_a_store_resumed_under_other_code_keeps_every_code_and_the_chunks_it_made(written):
    """The manifest kept only the last code, so a table of two codes' chunks named one (an
    audit): each chunk is listed under the code that made it, a recomputed chunk under its new
    maker alone."""
    folder, tasks = written
    set_manifest(folder, code=OLD_CODE, code_versions=[{"code": OLD_CODE, "chunks": [0, 1]}])
    store_in(folder).chunk_path(1).unlink()  # lost: recomputed by today's code
    store = store_in(folder)
    with pytest.warns(RuntimeWarning):
        assert store.open(tasks, resume=True) == [0]
    now = run_store.code_version()
    assert manifest_of(folder)["code_versions"] == [{"code": OLD_CODE, "chunks": [0]}]
    store.write(tasks[1], summary_of(tasks[1]))
    assert manifest_of(folder)["code_versions"] == store.code_versions() == [
        {"code": OLD_CODE, "chunks": [0]}, {"code": now, "chunks": [1]}]
    assert manifest_of(folder)["code"] == now  # the latest opening's, as before


def test_chunks_a_manifest_lists_under_no_code_are_its_last_openings(written):
    """A manifest from before code_versions (or a kill between a chunk and the manifest's
    update) lists some chunks under no code: they were made by its `code`, the version that
    opened the run last; without a manifest their maker is unknown (None)."""
    folder, tasks = written
    manifest = manifest_of(folder)
    del manifest["code_versions"]
    manifest["code"] = OLD_CODE
    assert run_store.makers_of_chunks(manifest, [0, 1]) == [{"code": OLD_CODE, "chunks": [0, 1]}]
    manifest["code_versions"] = [{"code": {"version": "x"}, "chunks": [1, 5]}]
    assert run_store.makers_of_chunks(manifest, [0, 1]) == [
        {"code": {"version": "x"}, "chunks": [1]}, {"code": OLD_CODE, "chunks": [0]}]
    assert run_store.makers_of_chunks(None, [1]) == [{"code": None, "chunks": [1]}]
    assert run_store.makers_of_chunks(manifest, []) == []


def test_resuming_another_definition_is_refused_naming_the_differences(written):
    folder, tasks = written
    other = RunStore(folder, definition_of(solver=SOLVER.replace(dt=1e-3, max_newton=30)),
                     flag="--run-dir")
    with pytest.raises(RunStoreError) as error:
        other.open(tasks, resume=True)
    message = str(error.value)
    assert message.startswith(f"--run-dir {folder} holds a run with another definition")
    assert "(solver.dt: 0.002 -> 0.001; solver.max_newton: 25 -> 30)" in message
    assert "\n" not in message
    assert len(list(folder.glob("chunk_*"))) == 2  # nothing deleted


def test_an_unfinished_run_is_not_restarted_without_resume(written):
    folder, tasks = written
    with pytest.raises(RunStoreError, match=r"run_dir .* holds an unfinished run \(2 of 2 "
                                            r"chunks done\): resume it"):
        store_in(folder).open(tasks, resume=False)
    assert len(list(folder.glob("chunk_*"))) == 2


def test_a_finished_or_empty_run_is_replaced_by_a_fresh_one(written):
    folder, tasks = written
    finishing = store_in(folder)
    finishing.open(tasks, resume=True)
    finishing.finish()
    assert store_in(folder).open(tasks, resume=False) == []
    assert list(folder.glob("chunk_*")) == []
    assert manifest_of(folder)["complete"] is False
    # an unfinished run with no chunk yet starts over too
    assert store_in(folder).open(tasks, resume=False) == []


def test_stale_temporary_files_of_a_killed_run_are_removed(written):
    folder, tasks = written
    stale = folder / ".chunk_000001.parquet.tmp-12345"
    stale.write_bytes(b"half a chunk")
    store_in(folder).open(tasks, resume=True)
    assert not stale.exists()


def test_folders_that_are_not_run_folders_are_refused(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("mine")
    with pytest.raises(RunStoreError, match=f"--run-dir {a_file}: exists and is not a folder"):
        RunStore(a_file, {}, flag="--run-dir").open([], resume=True)
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(RunStoreError, match=r"not empty and has no manifest.json; not a run "
                                            r"folder \(choose another run_dir\)"):
        RunStore(mine, {}).open([], resume=False)
    with pytest.raises(RunStoreError, match="cannot create it"):
        RunStore(a_file / "run", {}).open([], resume=False)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert store_in(empty).open(tasks_of(), resume=True) == []
    # a run set aside (`REPLACED`) by one killed before it wrote its first manifest: the folder
    # is empty for the next run, which deletes that one once it finishes
    from taichi_star.batch.store import REPLACED

    aside = tmp_path / "aside"
    (aside / REPLACED).mkdir(parents=True)
    store = store_in(aside)
    assert store.open(tasks_of(), resume=False) == []
    store.finish()
    assert not (aside / REPLACED).exists()


@pytest.mark.parametrize("text,reason", [("{", "(Expecting property name"),
                                         ("[]", "(no run definition in it)"),
                                         ('{"definition": 3}', "(no run definition in it)"),
                                         (b"\xff\xfe", "('utf-8' codec can't decode")])
def test_a_damaged_manifest_is_a_one_line_error_naming_the_reason(tmp_path, text, reason):
    folder = tmp_path / "run"
    folder.mkdir()
    path = folder / "manifest.json"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(RunStoreError) as error:
        RunStore(folder, {}, flag="--run-dir").read_manifest()
    message = str(error.value)
    assert message.startswith(f"--run-dir {folder}: manifest.json is damaged {reason}")
    # deleting the folder threw away the finished chunks that a resume without the manifest
    # keeps (an audit, 2026-12)
    assert message.endswith("; delete manifest.json and resume with the run's own arguments "
                            "(its chunk size too) to keep the chunks whose stamps match it, or "
                            "delete the folder (or choose another --run-dir) to start over")
    assert "\n" not in message


def test_a_manifest_whose_definition_was_edited_is_damaged_not_another_run(written):
    """A manifest's definition no longer matching its own definition_sha256 (an edited setting)
    is damage: the damaged-manifest error, whose advice keeps the chunks that match the run
    (it was refused as another run, with the advice to delete the folder: an audit, 2026-12);
    the manifest as written passes."""
    folder, tasks = written
    assert store_in(folder).read_manifest()["definition_sha256"] == \
        store_in(folder).definition_sha256
    definition = manifest_of(folder)["definition"]
    set_manifest(folder, definition={**definition,
                                     "chunk_size": definition["chunk_size"] + 1})
    with pytest.raises(RunStoreError, match=re.escape(
            f"run_dir {folder}: manifest.json is damaged (its definition does not match its "
            f"definition_sha256); delete manifest.json and resume")):
        store_in(folder).open(tasks, resume=True)


def test_stored_chunk_size_reads_the_manifest(written, tmp_path):
    folder, _ = written
    assert stored_chunk_size(folder) == CHUNK
    assert stored_chunk_size(tmp_path / "nowhere") is None
    assert stored_chunk_size(folder / "manifest.json") is None
    (tmp_path / "bare").mkdir()
    assert stored_chunk_size(tmp_path / "bare") is None


def git(folder, *arguments):
    return subprocess.run(["git", "-c", "user.name=test", "-c", "user.email=test@example.invalid",
                           *arguments], cwd=folder, capture_output=True, text=True,
                          check=True).stdout.strip()


@pytest.fixture
def checkout(tmp_path, monkeypatch):
    """A git checkout without commits holding taichi_star/provenance.py, seen by code_version
    as its source checkout (it looks one folder above the module); the test runs elsewhere."""
    if shutil.which("git") is None:
        pytest.skip("needs git")
    root = tmp_path / "checkout"
    module = root / "taichi_star" / "provenance.py"
    module.parent.mkdir(parents=True)
    module.write_text("# the module\n")
    git(root, "init", "-q")
    monkeypatch.setattr(provenance, "__file__", str(module))
    monkeypatch.chdir(tmp_path)
    return root


def files_sha256(*files):
    """The hash `code_version` gives a package of `files` ((path, bytes) pairs, in order of
    path), written out by hand: each path, the content's length and the content."""
    return hashlib.sha256(b"".join(f"{name}\0{len(content)}\0".encode() + content
                                   for name, content in files)).hexdigest()


THE_MODULE = files_sha256(("taichi_star/provenance.py", b"# the module\n"))
"""The hash of a package of one module, "# the module" (the fixtures' provenance.py)."""


def test_code_version_names_the_commit_and_whether_tracked_files_changed(checkout):
    git(checkout, "add", "-A")
    git(checkout, "commit", "-q", "-m", "first")
    head = git(checkout, "rev-parse", "HEAD")
    assert provenance.code_version() == {"version": ts.__version__, "commit": head,
                                        "dirty": False}
    (checkout / "notes.txt").write_text("untracked files do not count")
    assert provenance.code_version()["dirty"] is False
    (checkout / "taichi_star" / "provenance.py").write_text("# changed\n")
    diff = subprocess.run(["git", "diff", "HEAD", "--no-color", "--no-ext-diff"],
                          cwd=checkout, capture_output=True, check=True).stdout
    assert provenance.code_version() == {"version": ts.__version__, "commit": head,
                                        "dirty": True,
                                        "changes_sha256": hashlib.sha256(diff).hexdigest()}
    # another edit of the same commit is another version (a resume then warns)
    first = provenance.code_version()
    (checkout / "taichi_star" / "provenance.py").write_text("# changed again\n")
    assert provenance.code_version()["changes_sha256"] != first["changes_sha256"]


def test_a_sidecar_records_the_versions_of_the_libraries_that_shape_results(tmp_path):
    """`code_record`, and with it every sidecar (here `to_csv`'s), records the installed
    version of each library of `provenance.RECORDED_LIBRARIES`, and None for one that is not
    installed rather than failing. A result built by hand: no simulation."""
    import importlib.metadata

    from taichi_star.output import read_provenance, to_csv

    result = ts.SimulationResult(summary=pd.DataFrame({"gait": ["A1"], "alpha": [0.4]}),
                                 trajectory=pd.DataFrame(), shapes=None, topology=None,
                                 solver=SOLVER)
    recorded = read_provenance(to_csv(result, tmp_path / "run.csv"))["library_versions"]
    assert list(recorded) == list(provenance.RECORDED_LIBRARIES)
    # numpy and pandas come with every install, most others with the test extra, and torch
    # and SB3 where the machine has a CPU build of torch (.ci/run): each as installed here
    for name in provenance.RECORDED_LIBRARIES:
        try:
            installed = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            installed = None
        assert recorded[name] == installed, name
    assert recorded["numpy"] == np.__version__ and recorded["pandas"] == pd.__version__
    assert provenance.library_versions(("numpy", "no-such-distribution")) == {
        "numpy": np.__version__, "no-such-distribution": None}


def test_a_csv_sidecar_of_a_dirty_checkout_records_which_edits(checkout, tmp_path):
    """`SimulationResult.to_csv`'s sidecar records the hash of a dirty checkout's changes, as a
    study's sidecar does (both from `provenance.code_record`; the library's dropped it); a
    clean checkout's records none. A result built by hand: no simulation."""
    from taichi_star.output import read_provenance, to_csv

    git(checkout, "add", "-A")
    git(checkout, "commit", "-q", "-m", "first")
    result = ts.SimulationResult(summary=pd.DataFrame({"gait": ["A1"], "alpha": [0.4]}),
                                 trajectory=pd.DataFrame(), shapes=None, topology=None,
                                 solver=SOLVER)
    clean = read_provenance(to_csv(result, tmp_path / "clean.csv"))
    assert clean["git_dirty"] is False and "git_changes_sha256" not in clean
    (checkout / "taichi_star" / "provenance.py").write_text("# changed\n")
    diff = subprocess.run(["git", "diff", "HEAD", "--no-color", "--no-ext-diff"],
                          cwd=checkout, capture_output=True, check=True).stdout
    dirty = read_provenance(to_csv(result, tmp_path / "dirty.csv"))
    assert dirty["git_dirty"] is True
    assert dirty["git_changes_sha256"] == hashlib.sha256(diff).hexdigest()
    assert dirty["git_commit"] == git(checkout, "rev-parse", "HEAD")


def test_untracked_files_in_the_package_are_changes_and_in_their_hash(checkout):
    """A new module in taichi_star/ or studies/ changes what runs, but `git status
    --untracked-files=no` and `git diff HEAD` did not see it (an audit): dirty and hashed now,
    an ignored file there (bytecode) and an untracked file elsewhere not."""
    (checkout / ".gitignore").write_text("__pycache__/\n")
    git(checkout, "add", "-A")
    git(checkout, "commit", "-q", "-m", "first")
    head = git(checkout, "rev-parse", "HEAD")
    (checkout / "taichi_star" / "__pycache__").mkdir()
    (checkout / "taichi_star" / "__pycache__" / "x.pyc").write_bytes(b"ignored")
    (checkout / "notes.txt").write_text("not code")
    clean = {"version": ts.__version__, "commit": head, "dirty": False}
    assert provenance.code_version() == clean
    module = checkout / "taichi_star" / "newmod.py"
    module.write_text("A = 1\n")
    # the (empty) diff, then the file's path and content
    expected = hashlib.sha256(b"\0untracked\0taichi_star/newmod.py\0A = 1\n").hexdigest()
    assert provenance.code_version() == {**clean, "dirty": True, "changes_sha256": expected}
    module.write_text("A = 2\n")
    assert provenance.code_version()["changes_sha256"] not in (expected, None)
    module.unlink()
    (checkout / "studies").mkdir()
    (checkout / "studies" / "new_study.py").write_text("")
    assert provenance.code_version()["dirty"] is True


def test_a_package_inside_another_repository_records_no_commit(tmp_path, monkeypatch):
    """taichi_star installed into a .venv inside someone else's repository recorded that
    repository's commit, dirty flag and diff hash (an audit): the package's own checkout is a
    folder at the top of its repository whose HEAD holds this module; elsewhere the commit is
    unknown (None) and the package version alone says which code ran."""
    if shutil.which("git") is None:
        pytest.skip("needs git")
    other = tmp_path / "other"
    other.mkdir()
    git(other, "init", "-q")
    (other / ".gitignore").write_text(".venv/\n")
    (other / "tracked.txt").write_text("theirs\n")
    git(other, "add", "-A")
    git(other, "commit", "-q", "-m", "theirs")
    (other / "tracked.txt").write_text("edited\n")  # their checkout is dirty
    module = other / ".venv" / "site-packages" / "taichi_star" / "provenance.py"
    module.parent.mkdir(parents=True)
    module.write_text("# the module\n")
    monkeypatch.setattr(provenance, "__file__", str(module))
    unknown = {"version": ts.__version__, "commit": None, "dirty": None,
               "source_sha256": THE_MODULE}
    assert provenance.code_version() == unknown
    # at their top level but not in their commits (copied in, untracked): not its checkout
    vendored = other / "taichi_star" / "provenance.py"
    vendored.parent.mkdir()
    vendored.write_text("# the module\n")
    monkeypatch.setattr(provenance, "__file__", str(vendored))
    assert provenance.code_version() == unknown
    git(other, "add", "taichi_star")  # committed there, it is that checkout's code
    git(other, "commit", "-q", "-m", "vendored")
    assert provenance.code_version()["commit"] == git(other, "rev-parse", "HEAD")


def installed_beside(site, record, name="taichi_star", version=ts.__version__):
    """A dist-info of distribution `name` at `version` (default: this package's) in `site`,
    with `record` (a dict, a text, or None for none) as its direct_url.json."""
    info = site / f"{name}-{version}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name.replace('_', '-')}\n"
                                   f"Version: {version}\n")
    if record is not None:
        (info / "direct_url.json").write_text(
            record if isinstance(record, str) else json.dumps(record))


def git_record(commit_id, vcs="git"):
    return {"url": "https://example.invalid/taichi_star.git",
            "vcs_info": {"vcs": vcs, "commit_id": commit_id}}


SHA1 = "0123456789abcdef" * 2 + "01234567"


@pytest.mark.parametrize("record, commit", [
    (git_record(SHA1), SHA1),
    (git_record("0123456789abcdef" * 4), "0123456789abcdef" * 4),  # a SHA-256 repository
    (git_record(SHA1, vcs="hg"), None),  # a Mercurial node is 40 hex digits too
    ({"url": "file:///home/someone/taichi_star", "dir_info": {}}, None),
    (git_record("main"), None),  # a branch where a hash should be
    (git_record(SHA1 + "8"), None),  # 41 digits: no object name
    (git_record(SHA1.upper()), None),  # git writes lower case
    (git_record(123), None),
    ("not json {", None),
    (None, None),
])
def test_a_package_installed_from_a_git_url_records_the_commit_pip_recorded(
        tmp_path, monkeypatch, record, commit):
    """Outside a checkout no commit was recorded, even for `pip install git+URL@REF`, whose
    dist-info names the commit it installed (direct_url.json, PEP 610): now that commit, clean.
    Another version control, a folder's install, what is not a git object name, a damaged
    record or none: no commit, as before. A dist-info beside the package, no pip; another
    distribution's record beside it is not this package's."""
    site = tmp_path / "site-packages"
    module = site / "taichi_star" / "provenance.py"
    module.parent.mkdir(parents=True)
    module.write_text("# the module\n")
    installed_beside(site, record)
    installed_beside(site, git_record("f" * 40), name="other", version="1.0")
    monkeypatch.setattr(provenance, "__file__", str(module))
    named = {"version": ts.__version__, "commit": commit, "dirty": False if commit else None}
    # where no commit names the code, the hash of its files does
    assert provenance.code_version() == (named if commit else
                                         {**named, "source_sha256": THE_MODULE})


@pytest.mark.parametrize("beside, commit", [
    # another distribution's record is not this package's
    ([(git_record("f" * 40), "other", "1.0")], None),
    # an upgrade by `pip install --target` leaves the old version's dist-info: its record is
    # not the new code's (taken when listed first: a review, 2026-12), whichever is listed first
    ([(git_record("f" * 40), "taichi_star", "0.0.1"), (None, "taichi_star", None)], None),
    ([(git_record("f" * 40), "taichi_star", "0.0.1")], None),
    ([(git_record(SHA1), "taichi_star", None), (git_record("f" * 40), "taichi_star", "0.0.1")],
     SHA1),
    # the name as PEP 503 compares it
    ([(git_record(SHA1), "Taichi.Star", None)], SHA1),
    # a dist-info without metadata (a failed uninstall's) beside it is passed over
    ([(git_record(SHA1), "taichi_star", None), (None, None, None)], SHA1),
])
def test_only_this_versions_own_git_record_names_the_commit(tmp_path, monkeypatch, beside,
                                                            commit):
    site = tmp_path / "site-packages"
    module = site / "taichi_star" / "provenance.py"
    module.parent.mkdir(parents=True)
    module.write_text("# the module\n")
    for record, name, version in beside:
        if name is None:
            (site / "taichi_star-9.9.dist-info").mkdir()
            continue
        installed_beside(site, record, name=name, version=version or ts.__version__)
    monkeypatch.setattr(provenance, "__file__", str(module))
    assert provenance.code_version()["commit"] == commit


def test_code_version_with_a_damaged_git_index_names_the_commit_but_not_dirtiness(checkout):
    git(checkout, "add", "-A")
    git(checkout, "commit", "-q", "-m", "first")
    head = git(checkout, "rev-parse", "HEAD")
    (checkout / ".git" / "index").write_bytes(b"damaged")  # `git status` fails, HEAD is known
    assert provenance.code_version() == {"version": ts.__version__, "commit": head,
                                        "dirty": None}


def test_code_version_of_a_checkout_without_commits_names_none(checkout):
    # there `git rev-parse HEAD` fails yet prints "HEAD"
    assert provenance.code_version() == {"version": ts.__version__, "commit": None,
                                        "dirty": None, "source_sha256": THE_MODULE}


def test_code_version_without_git_names_none(checkout, monkeypatch):
    def no_git(*args, **kwargs):
        raise FileNotFoundError("git")
    monkeypatch.setattr(provenance.subprocess, "run", no_git)
    assert provenance.code_version() == {"version": ts.__version__, "commit": None,
                                        "dirty": None, "source_sha256": THE_MODULE}


def test_without_a_commit_the_hash_of_the_packages_files_names_the_code(tmp_path, monkeypatch):
    """A wheel or a folder's install recorded its version alone: two builds of one version,
    or an edited install, were one code, and a run store resumed with the other mixed their
    chunks unwarned (an audit). The hash covers every file of the package (data too) and, for
    a folder's install, the studies beside it, not byte code; a package with its own studies
    (an installed one) leaves a `studies` folder beside it (another distribution's) out; a
    file that cannot be read gives no hash."""
    site = tmp_path / "site-packages"
    module = site / "taichi_star" / "provenance.py"
    (site / "taichi_star" / "data").mkdir(parents=True)
    module.write_text("# the module\n")
    (site / "taichi_star" / "data" / "a.csv").write_bytes(b"t,x\n")
    (site / "taichi_star" / "__pycache__").mkdir()
    (site / "taichi_star" / "__pycache__" / "provenance.cpython-311.pyc").write_bytes(b"\0")
    (site / "taichi_star" / "stale.pyc").write_bytes(b"\1")
    (site / "studies").mkdir()
    (site / "studies" / "fig4c.py").write_text("# a study\n")
    monkeypatch.setattr(provenance, "__file__", str(module))
    package = [("taichi_star/data/a.csv", b"t,x\n"),
               ("taichi_star/provenance.py", b"# the module\n")]
    # a folder's install: the studies beside the package are its code
    assert provenance.code_version()["source_sha256"] == files_sha256(
        ("studies/fig4c.py", b"# a study\n"), *package)
    (site / "taichi_star" / "studies").mkdir()  # an installed package's own studies
    (site / "taichi_star" / "studies" / "fig4c.py").write_text("# its study\n")
    installed = files_sha256(*package, ("taichi_star/studies/fig4c.py", b"# its study\n"))
    assert provenance.code_version()["source_sha256"] == installed
    (site / "studies" / "fig4c.py").write_text("# someone else's\n")
    assert provenance.code_version()["source_sha256"] == installed
    (site / "taichi_star" / "data" / "a.csv").write_bytes(b"t,y\n")  # one byte of data
    assert provenance.code_version()["source_sha256"] != installed
    (site / "taichi_star" / "data" / "a.csv").unlink()
    (site / "taichi_star" / "data" / "a.csv").symlink_to(site / "missing.csv")
    assert provenance.code_version()["source_sha256"] is None


def test_write_atomic_writes_whole_or_leaves_the_previous_file(tmp_path, full_disk):
    """A write that fails before its rename (here: fsync reports a full disk) leaves the previous
    file byte for byte and no temporary file beside it; one that succeeds replaces it whole."""
    path = tmp_path / "table.csv"
    provenance.write_atomic(path, b"a,b\n1,2\n")
    assert path.read_bytes() == b"a,b\n1,2\n"

    with full_disk():
        with pytest.raises(OSError, match="No space left"):
            provenance.write_atomic(path, b"a,b\n3,4\n5,6\n")
    assert path.read_bytes() == b"a,b\n1,2\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]
    provenance.write_atomic(path, b"a,b\n3,4\n")
    assert path.read_bytes() == b"a,b\n3,4\n"
    # with a failure type: one line naming the file and the error, the file as it was
    with full_disk():
        with pytest.raises(ValueError, match=r"^cannot write table\.csv \(No space left on "
                                             r"device\)$"):
            provenance.write_atomic(path, b"x", failure=ValueError)
    assert path.read_bytes() == b"a,b\n3,4\n"


def test_write_atomic_syncs_the_folder_after_the_rename_and_goes_on_where_it_cannot(
        tmp_path, monkeypatch):
    """The file's data is synced before the rename and its folder after it (the rename itself
    outlives a power cut); a folder that cannot be synced (ENOTSUP, as some file systems
    answer) leaves a whole, renamed file and no error."""
    path = tmp_path / "table.csv"
    events = []
    real_fsync, real_replace = provenance.os.fsync, provenance.os.replace

    def logged_fsync(descriptor):
        events.append(("fsync", os.path.isdir(f"/proc/self/fd/{descriptor}")
                       and os.path.realpath(f"/proc/self/fd/{descriptor}")))
        real_fsync(descriptor)

    def logged_replace(source, target):
        events.append(("replace", str(target)))
        real_replace(source, target)

    monkeypatch.setattr(provenance.os, "fsync", logged_fsync)
    monkeypatch.setattr(provenance.os, "replace", logged_replace)
    provenance.write_atomic(path, b"a\n")
    assert events == [("fsync", False), ("replace", str(path)),
                      ("fsync", os.path.realpath(tmp_path))]

    def folder_unsupported(descriptor):
        if os.path.isdir(f"/proc/self/fd/{descriptor}"):
            raise OSError(errno.ENOTSUP, "Operation not supported")
        real_fsync(descriptor)

    monkeypatch.setattr(provenance.os, "fsync", folder_unsupported)
    provenance.write_atomic(path, b"b\n")
    assert path.read_bytes() == b"b\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_two_threads_writing_one_table_take_turns_and_keep_each_pair_whole(tmp_path):
    """Two threads of one process writing the same table and sidecar shared their temporary
    files (named by the process), each deleting the other's: 158 of 800 writes failed with
    "No such file or directory" and 6 of 40 rounds left a table without its sidecar (an
    audit, 2026-12). Now every write succeeds, and the last pair written is whole: the table
    with its own sidecar, no temporary left."""
    path = tmp_path / "table.csv"
    sidecar = tmp_path / "table.csv.json"
    start = threading.Barrier(2)
    failures = []

    def write(writer):
        start.wait()
        for number in range(100):
            try:
                provenance.write_atomic(path, f"{writer},{number}\n".encode() * 200,
                                        sidecar=(sidecar, f"{writer},{number}".encode()))
            except OSError as error:
                failures.append(error)
    threads = [threading.Thread(target=write, args=(writer,)) for writer in "ab"]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert failures == []
    assert path.read_bytes() == (sidecar.read_text() + "\n").encode() * 200
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv", "table.csv.json"]


# --- trajectories ---

def trajectory_of(task, records=3):
    """A chunk trajectory shaped like run_chunk's: instance, t_s and three coordinates per
    record, numbers whose last bits matter."""
    members = np.repeat(np.asarray(task.members, dtype=np.int64), records)
    times = np.tile(np.arange(records) * 0.02, len(task.members))
    return pd.DataFrame({"instance": members, "t_s": times, "x_mm": members / 7.0 + times,
                         "y_mm": -members / 3.0, "heading_deg": times * np.pi})


def test_a_chunks_trajectory_is_stored_beside_it_and_read_back_bitwise(tmp_path):
    folder = tmp_path / "run"
    tasks = tasks_of()
    store = store_in(folder)
    store.open(tasks, resume=False)
    store.write(tasks[0], summary_of(tasks[0]), trajectory_of(tasks[0]))
    store.write(tasks[1], summary_of(tasks[1]), trajectory_of(tasks[1]).iloc[:0])  # no records
    assert store.trajectory_path(0) == folder / "trajectory_000000.parquet"
    assert store.trajectory_path(0).exists() and not store.trajectory_path(1).exists()
    summary, trajectory = store.read_chunk(tasks[0])
    pd.testing.assert_frame_equal(trajectory, trajectory_of(tasks[0]), check_exact=True)
    pd.testing.assert_frame_equal(summary, store.read(tasks[0]), check_exact=True)
    assert store.read_chunk(tasks[1])[1] is None
    # the stamp ties the summary to its trajectory: resuming verifies both (once the first
    # run has let go of the folder, as its end or a kill of its process does)
    store.release()
    again = store_in(folder)
    assert again.open(tasks, resume=True) == [0, 1]


def test_a_damaged_or_swapped_trajectory_recomputes_its_chunk(tmp_path, caplog):
    folder = tmp_path / "run"
    tasks = tasks_of(params=PARAMS * 3)   # four chunks of three instances
    assert len(tasks) == 4
    store = RunStore(folder, definition_of(params=PARAMS * 3))
    store.open(tasks, resume=False)
    for task in tasks:
        store.write(task, summary_of(task), trajectory_of(task))
    # chunk 0: its trajectory's bytes cut; chunk 1: chunk 2's trajectory (same size, its own
    # stamp) put in its place; chunk 2: its trajectory deleted
    path = store.trajectory_path(0)
    path.write_bytes(path.read_bytes()[:-20])
    shutil.copy(store.trajectory_path(2), store.trajectory_path(1))
    store.trajectory_path(2).unlink()
    store.release()   # the run ends
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        done = RunStore(folder, definition_of(params=PARAMS * 3)).open(tasks, resume=True)
    assert done == [3]   # the one chunk left whole
    reasons = caplog.text
    assert "its trajectory unreadable" in reasons
    assert "its trajectory holds another chunk's instances" in reasons
    assert "its trajectory unreadable (No such file or directory)" in reasons
    for index in (0, 1, 2):
        assert not store.chunk_path(index).exists() and not store.trajectory_path(index).exists()


def written_with_trajectories(folder):
    """(store, tasks) of a run whose two chunks are written with their trajectories."""
    tasks = tasks_of()
    store = store_in(folder)
    store.open(tasks, resume=False)
    for task in tasks:
        store.write(task, summary_of(task), trajectory_of(task))
    return store, tasks


def test_a_folder_of_chunks_and_trajectories_without_a_manifest_is_resumable(tmp_path):
    folder = tmp_path / "run"
    store, tasks = written_with_trajectories(folder)
    store.release()   # the run ends
    (folder / "manifest.json").unlink()
    assert store_in(folder).open(tasks, resume=True) == [0, 1]


def test_a_trajectory_changed_after_open_is_an_error_naming_the_chunk(tmp_path):
    """Between `open` and the final read a chunk's trajectory replaced by another of the same
    chunk (its own stamp valid) no longer matches the checksum its summary holds; one cut
    short is unreadable: both a RunStoreError naming the chunk file and why."""
    store, tasks = written_with_trajectories(tmp_path / "run")
    store._write_table(store.trajectory_path(0), tasks[0], trajectory_of(tasks[0], records=2))
    with pytest.raises(RunStoreError) as error:
        store.read_chunk(tasks[0])
    assert str(error.value) == (f"{store.chunk_path(0)}: its trajectory is another one than the "
                                f"summary's")
    path = store.trajectory_path(1)
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(RunStoreError, match=rf"^{re.escape(str(store.chunk_path(1)))}: its "
                                            rf"trajectory unreadable \("):
        store.read(tasks[1])


# --- what a store of another version left, and files that cannot be read ---

def test_a_run_of_the_format_before_is_refused_saying_why(written):
    """Format 2 defined a run by every parameter field, so a field added later with its default
    made its runs unresumable, blamed on "the instance parameters" (an audit, 2026-12); format 3
    records the fields that differ from their defaults. A format-2 run is refused naming both
    formats, its chunks kept."""
    folder, tasks = written
    manifest = manifest_of(folder)
    manifest["definition"]["format"] = 2
    manifest["definition_sha256"] = hashlib.sha256(json.dumps(
        manifest["definition"], sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RunStoreError, match=re.escape(
            f"run_dir {folder} holds a run in the store's format 2, this version's is 3 (a run "
            f"is now defined by the settings that differ from their defaults); refusing to "
            f"resume it: finish it with the version that started it, or delete the folder")):
        store_in(folder).open(tasks, resume=True)
    assert len(list(folder.glob("chunk_*"))) == 2


def test_a_parameter_at_its_default_leaves_the_definition_as_without_it():
    """A field set to its default value is no change: the definition of instances that set
    one is that of instances that leave it (so a field added with a default that changes
    nothing keeps every run's definition)."""
    explicit = [p.replace(cylinder_drag=ts.StarParams().cylinder_drag) for p in PARAMS]
    assert definition_of(explicit) == definition_of()
    assert definition_of(solver=SOLVER.replace(max_newton=ts.SolverConfig().max_newton)) \
        == definition_of()


@pytest.fixture
def unreadable(monkeypatch):
    """Files whose name is in the returned set cannot be read (EACCES), as a file of another
    user or on a failing disk (root reads every file whatever its mode)."""
    names = set()
    read_bytes = Path.read_bytes

    def refusing(path):
        if path.name in names:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return read_bytes(path)
    monkeypatch.setattr(Path, "read_bytes", refusing)
    return names


@pytest.mark.parametrize("name", ["chunk_000000.parquet", "manifest.json"])
def test_a_file_that_cannot_be_read_is_named_and_nothing_is_deleted(written, unreadable, name):
    """An unreadable chunk was taken for a damaged one, deleted and recomputed, and an
    unreadable manifest called damaged with the advice to delete it (an audit, 2026-12): the
    run is refused naming the file, every file left."""
    folder, tasks = written
    unreadable.add(name)
    def files():  # the lock is the holder's, whoever it is
        return sorted(path.name for path in folder.iterdir() if path.name != LOCK)
    before = files()
    with pytest.raises(RunStoreError, match=re.escape(
            f"{folder / name}: cannot be read (Permission denied); the run folder is left as "
            f"it is: make the file readable, or choose another run folder")):
        store_in(folder).open(tasks, resume=True)
    assert files() == before and "chunk_000000.parquet" in before


def test_a_chunk_stored_without_the_trajectory_its_run_records_is_recomputed(tmp_path, caplog):
    """Every run with records has one at its start: a chunk stamped without a trajectory (as
    a store before trajectories were kept wrote it) dropped its instances' records from the
    result without a word (an audit, 2026-12); now it is recomputed."""
    folder = tmp_path / "run"
    tasks = tasks_of(record_interval_s=0.02)
    store = RunStore(folder, definition_of(record_interval_s=0.02))
    store.open(tasks, resume=False)
    for task in tasks:
        store.write(task, summary_of(task), trajectory_of(task))
    store.release()
    path = store.chunk_path(0)
    rewrite(path, stamp_changes={})   # the same stamp ...
    table = pq.read_table(path)
    stamp = json.loads(table.schema.metadata[b"taichi_star.chunk"])
    del stamp["trajectory_sha256"]    # ... without its trajectory's
    pq.write_table(table.replace_schema_metadata(
        {**table.schema.metadata, b"taichi_star.chunk": json.dumps(stamp).encode()}), path)
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        assert RunStore(folder, definition_of(record_interval_s=0.02)).open(
            tasks, resume=True) == [1]
    assert [r.getMessage() for r in caplog.records] == [
        f"{path}: stored without its trajectory, which this run records; recomputing it"]


def test_a_resume_under_changed_defaults_is_refused_naming_them(written):
    """A definition holds what differs from the defaults, so a version that changed a default
    would have gone on under the new value without a word (a review, 2026-12): the manifest
    records the defaults, and a resume where one differs is refused naming it; a field added
    since (missing from the record) is no change."""
    folder, tasks = written
    manifest = manifest_of(folder)
    assert manifest["defaults"] == run_store.current_defaults()
    assert manifest["defaults"]["params"]["alpha"] == ts.StarParams().alpha
    del manifest["defaults"]["params"]["cylinder_drag"]   # a field added since
    (folder / "manifest.json").write_text(json.dumps(manifest))
    store = store_in(folder)
    assert store.open(tasks, resume=True) == [0, 1]
    store.release()
    manifest = manifest_of(folder)
    manifest["defaults"]["solver"]["max_newton"] = 12   # started when the default was 12
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RunStoreError, match=re.escape(
            f"(the default solver.max_newton: 12 -> {ts.SolverConfig().max_newton})")):
        store_in(folder).open(tasks, resume=True)
