"""The run store: a resumed run recomputes (never loads) chunks that are truncated, random bytes,
empty or from another run, and ends with the table of an uninterrupted run; a damaged manifest
is a one-line error (exit 2 from the command line); a store refuses another definition."""

import contextlib
import errno
import json
import logging
import os
import re
import socket
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import taichi_star as ts
from taichi_star.actuation import CurvatureProfile
from taichi_star.batch import RunStore, RunStoreError, run_batch
from taichi_star.batch.tasks import ChunkTask
from taichi_star import provenance
from taichi_star.output import read_provenance

from studies.__main__ import main as studies_main

SOLVER = ts.SolverConfig(dt=2e-3)
PARAMS = [ts.StarParams(gait=g, alpha=a) for g in ("A1", "A1+A3") for a in (0.4, 0.8, 1.2)]
DURATION = 0.1
CHUNK = 2  # three chunks


def run(run_dir, resume=False, params=PARAMS):
    return run_batch(params, DURATION, solver=SOLVER, chunk_size=CHUNK, run_dir=run_dir,
                     resume=resume).summary


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """(run folder, its summary) of an uninterrupted run."""
    folder = tmp_path_factory.mktemp("store") / "run"
    return folder, run(folder)


def unfinished_copy(source, folder, **manifest_changes):
    """`folder`, a copy of the finished run folder `source` whose manifest says it is not
    finished (a run to resume), with `manifest_changes` to its manifest (complete=True: a
    finished one)."""
    folder.mkdir()
    for path in source.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest.update({"complete": False, **manifest_changes})
    (folder / "manifest.json").write_text(json.dumps(manifest))
    return folder


def test_stored_run_equals_a_plain_run(finished):
    folder, summary = finished
    plain = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=CHUNK).summary
    pd.testing.assert_frame_equal(summary, plain, check_exact=True)
    manifest = json.loads((folder / "manifest.json").read_text())
    assert manifest["complete"] is True
    definition = manifest["definition"]
    assert definition["n_chunks"] == 3 and definition["duration_s"] == DURATION
    assert definition["solver"]["dt"] == SOLVER.dt and definition["arch"] == "cpu"
    assert manifest["code"]["version"] == ts.__version__
    assert sorted(p.name for p in folder.iterdir()) == [
        "chunk_000000.parquet", "chunk_000001.parquet", "chunk_000002.parquet", "manifest.json"]


def damage_truncated(path, other):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def damage_random(path, other):
    path.write_bytes(bytes(range(256)) * 8)


def damage_empty(path, other):
    path.write_bytes(b"")


def damage_foreign(path, other):
    path.write_bytes((other / path.name).read_bytes())


def damage_tampered(path, other):
    """A value changed in the last bit, the chunk's metadata (and checksum) kept."""
    table = pq.read_table(path)
    frame = table.to_pandas()
    frame.loc[0, "speed_mm_s"] = np.nextafter(frame.loc[0, "speed_mm_s"], np.inf)
    changed = pa.Table.from_pandas(frame, preserve_index=False)
    pq.write_table(changed.replace_schema_metadata(table.schema.metadata), path)


@pytest.mark.parametrize("damage", [damage_truncated, damage_random, damage_empty, damage_foreign,
                                    damage_tampered])
def test_damaged_chunk_is_reported_and_recomputed(finished, tmp_path, damage, caplog,
                                                  monkeypatch):
    source, summary = finished
    folder = unfinished_copy(source, tmp_path / "run")
    other = tmp_path / "other"  # same chunking, other parameters
    run(other, params=[p.replace(cylinder_drag=20.0) for p in PARAMS])
    damage(folder / "chunk_000001.parquet", other)

    computed = []
    original = ts.batch.tasks.run_chunk

    def counting(task, progress=False):
        computed.append(task.index)
        return original(task, progress)
    monkeypatch.setattr(ts.batch.executors, "run_chunk", counting)
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        resumed = run(folder, resume=True)
    assert computed == [1]
    assert "chunk_000001.parquet" in caplog.text and "recomputing" in caplog.text
    pd.testing.assert_frame_equal(resumed, summary, check_exact=True)


@pytest.mark.parametrize("text", ["{", "", "[]", '{"definition": 3}', "\x00\x01"])
def test_damaged_manifest_is_a_one_line_error(finished, tmp_path, text, monkeypatch, capsys):
    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "manifest.json").write_text(text)
    with pytest.raises(RunStoreError) as error:
        run(folder, resume=True)
    message = str(error.value)
    assert "manifest.json is damaged" in message and "\n" not in message
    # from the command line: exit 2, one line, nothing computed
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    code = studies_main(["sweep", "--gaits", "A1", "--quick", "--no-progress", "--out",
                         str(tmp_path / "out"), "--run-dir", str(folder), "--resume"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "manifest.json is damaged" in err and len(err.splitlines()) == 1
    # named by the study's flag, also where the resume reads the stored chunk size first
    # (it said run_dir there: a review, 2026-12)
    assert f"--run-dir {folder}: manifest.json is damaged" in err, err


def test_another_definition_or_an_unfinished_run_is_refused(finished, tmp_path, monkeypatch):
    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    for path in source.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with pytest.raises(RunStoreError, match=r"another definition.*solver.dt: 0.002 -> 0.001"):
        run_batch(PARAMS, DURATION, solver=SOLVER.replace(dt=1e-3), chunk_size=CHUNK,
                  run_dir=folder, resume=True)
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["complete"] = False
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RunStoreError, match="unfinished run"):
        run(folder)
    not_a_run = tmp_path / "mine"
    not_a_run.mkdir()
    (not_a_run / "notes.txt").write_text("mine")
    with pytest.raises(RunStoreError, match="not a run folder"):
        RunStore(not_a_run, {}).open([], resume=True)


def _forbidden(*args, **kwargs):
    raise AssertionError("simulate was called despite a refused run folder")


def test_every_bit_flip_in_a_chunks_metadata_is_damage_or_harmless(tmp_path):
    """A chunk's Parquet footer (its schema, the pandas and Arrow metadata and the stamp) with
    one bit flipped, for every byte of it (the flipped bit cycling through the 8 positions,
    2,475 flips of a 2-column chunk): decoding either refuses it as damage (ValueError, so the
    chunk is recomputed) or gives the very table written; never another exception (a crash of
    --resume: before, 40 of 1,552 such flips raised KeyError or TypeError from `to_pandas`) and
    never other data. One bit per byte keeps the loop under ~5 s (2 ms per decode)."""
    task = ChunkTask(0, (0,), (ts.StarParams(),), DURATION, SOLVER)
    written = pd.DataFrame({"speed_mm_s": [0.1], "actuator_profile": [CurvatureProfile()]})
    store = RunStore(tmp_path, {"a": "definition"})
    data = store.write(task, written).read_bytes()
    original = store.decode_chunk(data, task)[0]
    pd.testing.assert_frame_equal(original, written, check_exact=True)
    footer_length = int.from_bytes(data[-8:-4], "little")
    outcomes = {"damage": 0, "same": 0}
    for position in range(len(data) - 8 - footer_length, len(data)):
        flipped = bytearray(data)
        flipped[position] ^= 1 << (position % 8)
        try:
            decoded = store.decode_chunk(bytes(flipped), task)[0]
        except ValueError:
            outcomes["damage"] += 1
            continue
        assert decoded.equals(original), f"byte {position} flipped: other data, not refused"
        outcomes["same"] += 1
    assert sum(outcomes.values()) == footer_length + 8
    assert outcomes["damage"] > 0 and outcomes["same"] > 0


def test_a_deleted_manifest_lets_the_stamped_chunks_be_reused(finished, tmp_path, monkeypatch,
                                                             caplog):
    """Each chunk carries its run's definition hash: without manifest.json, --resume reuses
    the chunks (none recomputed) and gives the uninterrupted table; without resume the folder
    is refused with a message saying to resume."""
    source, summary = finished
    folder = tmp_path / "run"
    folder.mkdir()
    for path in source.glob("chunk_*.parquet"):
        (folder / path.name).write_bytes(path.read_bytes())
    with pytest.raises(RunStoreError, match="no manifest.json: resume to reuse"):
        run(folder)
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    with caplog.at_level(logging.WARNING, logger="taichi_star.batch"):
        resumed = run(folder, resume=True)
    assert "has no manifest.json" in caplog.text
    pd.testing.assert_frame_equal(resumed, summary, check_exact=True)
    assert json.loads((folder / "manifest.json").read_text())["complete"] is True


def test_a_full_disk_is_a_run_store_error_naming_the_folder(tmp_path, monkeypatch):
    """ENOSPC while writing a chunk: RunStoreError naming the folder (one line), the files
    written before intact."""
    task = ChunkTask(0, (0,), (ts.StarParams(),), DURATION, SOLVER)
    store = RunStore(tmp_path / "run", {"a": "definition"})
    store.open([task], resume=False)
    manifest = (tmp_path / "run" / "manifest.json").read_bytes()

    def full_disk(source, target):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr("taichi_star.provenance.os.replace", full_disk)
    with pytest.raises(RunStoreError) as error:
        store.write(task, pd.DataFrame({"speed_mm_s": [0.1]}))
    message = str(error.value)
    assert str(tmp_path / "run") in message and "No space left" in message
    assert "\n" not in message
    assert (tmp_path / "run" / "manifest.json").read_bytes() == manifest


def test_without_a_manifest_another_runs_chunks_are_refused_not_replaced(finished, tmp_path,
                                                                        monkeypatch):
    """A folder of chunk files whose manifest is gone, resumed with other arguments: every
    chunk was logged as "from another run", deleted and recomputed: the earlier run's results
    lost (an audit). Now refused before anything is touched or computed."""
    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    for path in source.glob("*.parquet"):
        (folder / path.name).write_bytes(path.read_bytes())
    before = {path.name: path.read_bytes() for path in folder.iterdir()}
    monkeypatch.setattr("taichi_star.batch.tasks.simulate", _forbidden)
    other = [p.replace(alpha=p.alpha + 0.1) for p in PARAMS]
    with pytest.raises(RunStoreError, match=r"has no manifest.json and holds chunks of another "
                                            r"run \(chunk_000000.parquet"):
        run(folder, resume=True, params=other)
    assert {path.name: path.read_bytes() for path in folder.iterdir()} == before


def test_a_folder_left_with_only_a_killed_first_manifest_write_starts_afresh(finished,
                                                                            tmp_path):
    """A run killed while writing its first manifest left only ".manifest.json.tmp-PID": the
    folder was "not a run folder" to a resume and to a new run alike (an audit). It is empty
    to both now, and the temporary file goes."""
    _, summary = finished
    for resume in (False, True):
        folder = tmp_path / f"run_{resume}"
        folder.mkdir()
        (folder / ".manifest.json.tmp-12345").write_bytes(b'{"defin')
        pd.testing.assert_frame_equal(run(folder, resume=resume), summary, check_exact=True)
        assert not list(folder.glob(".*.tmp-*"))


@pytest.mark.parametrize("change, reason", [
    (lambda manifest: manifest.update(resumed=5), "its resumed entry is not a list"),
    (lambda manifest: manifest.update(complete="yes"), "its complete entry is not true or false"),
    (lambda manifest: manifest["definition"].update(chunk_size="8"),
     "its chunk size '8' is not a whole number >= 1"),
    (lambda manifest: manifest["definition"].update(chunk_size=0),
     "its chunk size 0 is not a whole number >= 1"),
    (lambda manifest: manifest.update(code_versions={"code": None}),
     "its code_versions entry is not a list of code versions, each with its chunks"),
    (lambda manifest: manifest.update(code_versions=[{"code": None, "chunks": ["0"]}]),
     "its code_versions entry is not a list of code versions, each with its chunks"),
])
def test_a_manifest_of_the_wrong_kinds_is_damage(finished, tmp_path, change, reason):
    """Valid JSON with entries of the wrong kind raised a TypeError or another library's
    ValueError (exit 1 with a traceback from the command line); now a one-line damage."""
    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    manifest = json.loads((source / "manifest.json").read_text())
    change(manifest)
    (folder / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RunStoreError, match=f"manifest.json is damaged \\({reason}\\)"):
        run(folder, resume=True)


def test_a_batch_resumed_under_other_code_says_so_in_its_result_files(finished, tmp_path):
    """A resumed store mixing two codes' chunks: the manifest kept only the last code, and the
    result's files named only the writer's (an audit). The result and its files list each
    code with its chunks; a store of one code adds nothing (the other side)."""
    source, summary = finished
    old = {"version": "0.0.1", "commit": "abc", "dirty": False}
    folder = unfinished_copy(source, tmp_path / "run", code=old,
                             code_versions=[{"code": old, "chunks": [0, 1, 2]}])
    (folder / "chunk_000002.parquet").unlink()
    with pytest.warns(RuntimeWarning, match="resuming a run started with code"):
        result = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=CHUNK, run_dir=folder,
                           resume=True)
    pd.testing.assert_frame_equal(result.summary, summary, check_exact=True)
    now = provenance.code_version()
    makers = [{"code": old, "chunks": [0, 1]}, {"code": now, "chunks": [2]}]
    assert result.code_versions == makers and result.arch == "cpu"
    assert json.loads((folder / "manifest.json").read_text())["code_versions"] == makers
    assert read_provenance(result.to_csv(tmp_path / "r.csv"))["code_versions"] == makers
    one_code = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=CHUNK,
                         run_dir=tmp_path / "fresh")
    assert one_code.code_versions is None
    assert "code_versions" not in read_provenance(one_code.to_csv(tmp_path / "fresh.csv"))
    # a finished run of another code read back: said, and its result names its maker (it named
    # the reading code alone, without a word: an audit, 2026-12); of this code, nothing
    made_before = unfinished_copy(source, tmp_path / "before", code=old, complete=True,
                                  code_versions=[{"code": old, "chunks": [0, 1, 2]}])
    with pytest.warns(RuntimeWarning, match=r"^reading back a run made with code \[\{"):
        read_back = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=CHUNK,
                              run_dir=made_before, resume=True)
    pd.testing.assert_frame_equal(read_back.summary, summary, check_exact=True)
    assert read_back.code_versions == [{"code": old, "chunks": [0, 1, 2]}]
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        again = run_batch(PARAMS, DURATION, solver=SOLVER, chunk_size=CHUNK,
                          run_dir=tmp_path / "fresh", resume=True)
    assert again.code_versions is None


def test_a_file_the_store_cannot_remove_is_a_run_store_error(finished, tmp_path, monkeypatch):
    """A damaged chunk in a read-only folder: the unlink's OSError came raw (a 38-line
    traceback from the command line; an audit); now one line naming the file."""
    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    for path in source.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())
    (folder / "chunk_000001.parquet").write_bytes(b"damaged")
    real_unlink = type(folder).unlink

    def read_only(path, missing_ok=False):
        if path.parent == folder:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS))
        return real_unlink(path, missing_ok=missing_ok)

    monkeypatch.setattr(type(folder), "unlink", read_only)
    with pytest.raises(RunStoreError) as error:
        run(folder, resume=True)
    message = str(error.value)
    assert "cannot remove chunk_000001.parquet (Read-only file system)" in message
    assert "\n" not in message


def test_a_folder_in_use_by_another_run_is_refused_and_free_once_it_ends(tmp_path):
    """Two runs in one folder replaced each other's manifest and chunks without a word (an
    audit, 2026-12): a run holds its folder (`LOCK`, its process and machine) until it ends;
    another is refused naming the holder, and takes the folder once the first let go."""
    from taichi_star.batch.store import LOCK

    task = ChunkTask(0, (0,), (ts.StarParams(),), DURATION, SOLVER)
    folder = tmp_path / "run"
    first = RunStore(folder, {"a": "definition"})
    first.open([task], resume=False)
    assert (folder / LOCK).read_text() == f"{os.getpid()} {socket.gethostname()}"
    with pytest.raises(RunStoreError) as error:
        RunStore(folder, {"b": "definition"}).open([task], resume=False)
    assert str(error.value) == (
        f"run_dir {folder} is in use by another run (process {os.getpid()} on this machine "
        f"(this one: another call in it holds the folder)); wait for it to end or choose "
        f"another run_dir (if no run uses the folder, delete {folder / LOCK})")
    assert json.loads((folder / "manifest.json").read_text())["definition"] == {
        "a": "definition"}   # untouched
    first.release()
    assert not (folder / LOCK).exists()
    second = RunStore(folder, {"a": "definition"})
    assert second.open([task], resume=True) == []
    second.release()


def folder_of_a_killed_run(tmp_path):
    """(run folder, its lock file, a one-instance task): the folder holds the lock a killed
    run left, naming a process of this machine that has ended."""
    import subprocess
    from taichi_star.batch.store import LOCK

    folder = tmp_path / "run"
    folder.mkdir()
    ended = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                           capture_output=True, text=True, check=True).stdout.strip()
    (folder / LOCK).write_text(f"{ended} {socket.gethostname()}")
    return folder, folder / LOCK, ChunkTask(0, (0,), (ts.StarParams(),), DURATION, SOLVER)


@contextlib.contextmanager
def held_by_a_live_process(lock):
    """The lock file names a process of this machine that is alive (a sleeping child) while
    the block runs; the refusal a run then meets names it (`refused_by`)."""
    import subprocess

    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock.write_text(f"{holder.pid} {socket.gethostname()}")
        yield holder.pid
    finally:
        holder.kill()
        holder.wait()


def refused_by(pid):
    return pytest.raises(RunStoreError, match=re.escape(
        f"is in use by another run (process {pid} on this machine)"))


def test_a_lock_of_an_ended_process_is_taken_over_and_one_of_another_machine_refused(tmp_path):
    """A killed run leaves its lock: a process of this machine that has ended holds nothing
    (taken over); one of another machine may still run (refused, named)."""
    from taichi_star.batch.store import LOCK

    folder, _, task = folder_of_a_killed_run(tmp_path)
    store = RunStore(folder, {"a": "definition"})
    assert store.open([task], resume=False) == []
    assert (folder / LOCK).read_text() == f"{os.getpid()} {socket.gethostname()}"
    store.release()
    (folder / LOCK).write_text("123 another-machine")
    with pytest.raises(RunStoreError, match=r"is in use by another run \(process 123 on machine "
                                            r"another-machine\)"):
        RunStore(folder, {"a": "definition"}).open([task], resume=True)


@pytest.mark.skipif(sys.platform == "win32", reason="fcntl.flock is POSIX")
def test_of_two_runs_taking_over_an_ended_runs_lock_only_one_gets_it(tmp_path):
    """Two resumes of a killed run's folder each read the lock of the ended process, then
    each removed it and made its own: both ran in one folder (an audit, 2026-12). A run that
    takes the folder holds the lock file under flock before it reads who the file names, so
    the second, whose flock fails, is refused even while the file still names the ended
    process (the moment between the first's flock and its writing itself in); and once the
    first lets go (its process ends: the system closes the file) the folder is taken."""
    import fcntl
    from taichi_star.batch.store import LOCK

    folder, lock, task = folder_of_a_killed_run(tmp_path)
    with open(lock) as first:   # the first run's hold, not yet written in
        fcntl.flock(first, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(RunStoreError, match=re.escape(
                f"run_dir {folder} is in use by another run (a run starting now)")):
            RunStore(folder, {"a": "definition"}).open([task], resume=True)
    store = RunStore(folder, {"a": "definition"})
    assert store.open([task], resume=True) == []
    assert (folder / LOCK).read_text() == f"{os.getpid()} {socket.gethostname()}"
    store.release()
    assert not (folder / LOCK).exists()


def test_a_live_runs_lock_that_cannot_be_opened_still_refuses_the_folder(tmp_path, monkeypatch):
    """Another user's lock file cannot be opened for writing; the folder is then taken for a
    read-only one (not locked) only where no live run holds it: a live holder is named and
    the run refused, as when the lock is open."""
    from taichi_star.batch import store as run_store

    folder, lock, task = folder_of_a_killed_run(tmp_path)
    with held_by_a_live_process(lock) as pid:
        opener = os.open

        def refused(path, *args, **kwargs):
            if os.fspath(path) == os.fspath(lock):
                raise PermissionError(errno.EACCES, "Permission denied", str(path))
            return opener(path, *args, **kwargs)
        monkeypatch.setattr(run_store.os, "open", refused)
        with refused_by(pid):
            RunStore(folder, {"a": "definition"}).open([task], resume=True)


def test_an_ended_runs_lock_that_cannot_be_opened_is_taken_over(tmp_path, monkeypatch):
    """Another user's lock file, of a run that has ended, in a folder this run may write: it
    was left, and the run went on without a lock (a review, 2026-12); now it is removed and the
    folder locked."""
    from taichi_star.batch import store as run_store

    folder, lock, task = folder_of_a_killed_run(tmp_path)
    opener = os.open

    def refused(path, *args, **kwargs):
        if os.fspath(path) == os.fspath(lock) and lock.exists():
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        return opener(path, *args, **kwargs)
    monkeypatch.setattr(run_store.os, "open", refused)
    store = RunStore(folder, {"a": "definition"})
    assert store.open([task], resume=True) == []
    assert store.locked and lock.read_text() == f"{os.getpid()} {socket.gethostname()}"
    store.release()


def test_without_flock_the_lock_is_made_exclusively(tmp_path, monkeypatch):
    """Where the system has no flock (Windows) the lock file is created exclusively again, its
    holder deciding: a live run's refuses the folder, an ended run's is taken over (without
    O_EXCL, two new runs could both write themselves into an empty file: a review, 2026-12)."""
    from taichi_star.batch import store as run_store

    monkeypatch.setattr(run_store, "fcntl", None)
    folder, lock, task = folder_of_a_killed_run(tmp_path)
    store = RunStore(folder, {"a": "definition"})
    assert store.open([task], resume=True) == []   # the ended run's lock taken over
    store.release()
    with held_by_a_live_process(lock) as pid, refused_by(pid):
        RunStore(folder, {"a": "definition"}).open([task], resume=True)


def test_run_batch_lets_go_of_its_folder_after_a_failure_and_reads_a_finished_run_back_read_only(
        tmp_path, monkeypatch):
    """A run_batch that fails lets go of its folder (a retry in the same process, a notebook's,
    resumes it); one that ends too. Reading a finished run back writes nothing: a store on
    read-only media could not be read back (its manifest was rewritten: an audit, 2026-12)."""
    from taichi_star.batch import store as run_store

    folder = tmp_path / "run"
    original = run_store.RunStore.write

    def failing_second(self, task, *args, **kwargs):
        if task.index == 1:
            raise OSError("a fault in the middle of the run")
        return original(self, task, *args, **kwargs)

    monkeypatch.setattr(run_store.RunStore, "write", failing_second)
    with pytest.raises(OSError, match="a fault in the middle"):
        run(folder)
    assert not (folder / run_store.LOCK).exists()
    monkeypatch.undo()
    summary = run(folder, resume=True)
    assert not (folder / run_store.LOCK).exists()

    def no_writes(*args, **kwargs):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS))
    monkeypatch.setattr(run_store, "write_atomic", no_writes)
    monkeypatch.setattr(run_store.os, "open", no_writes)   # nor a lock file
    pd.testing.assert_frame_equal(run(folder, resume=True), summary, check_exact=True)


def test_a_finished_run_replaced_by_a_new_one_is_said_and_kept_until_that_one_finishes(
        finished, tmp_path):
    """run_batch(run_dir=D) without resume replaces a finished run in D (resume reads it back);
    it did so without a word (an audit, 2026-12): a RuntimeWarning names the folder and the
    chunks replaced. The finished run waits in replaced_run/ until the new one finishes (it was
    deleted as the new one began, and a new run that failed left neither: an audit, 2026-12),
    its files and manifest as they were. An empty folder is taken without a warning."""
    from taichi_star.batch.store import REPLACED

    source, _ = finished
    folder = tmp_path / "run"
    folder.mkdir()
    for path in source.iterdir():
        (folder / path.name).write_bytes(path.read_bytes())

    class Failing:
        def run(self, tasks, progress=False):
            raise KeyboardInterrupt  # the new run stopped before its first chunk

    with pytest.warns(RuntimeWarning, match=rf"^run_dir {folder} held a finished run \(3 "
                                            rf"chunk\(s\), created .*\): replaced by this one, "
                                            rf"kept in {REPLACED}/ until this one finishes"):
        with pytest.raises(KeyboardInterrupt):
            run_batch(PARAMS[:1], DURATION, solver=SOLVER, chunk_size=CHUNK, run_dir=folder,
                      executor=Failing())
    for path in source.iterdir():
        kept = folder / REPLACED / path.name
        assert kept.read_bytes() == path.read_bytes(), path.name
    # the new run, resumed, finishes: the finished run it replaced goes
    run(folder, resume=True, params=PARAMS[:1])
    assert not (folder / REPLACED).exists()
    assert sorted(p.name for p in folder.iterdir() if p.suffix == ".parquet") == [
        "chunk_000000.parquet"]
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        run(tmp_path / "empty", params=PARAMS[:1])


def test_an_interrupt_before_the_first_chunk_lets_go_of_the_folder(tmp_path, monkeypatch):
    """An interrupt between the folder's opening and the chunks' start (the progress bar's
    set-up) kept the folder locked, and a retry in the same process was refused as another
    run's (an audit, 2026-12): the lock goes, and the retry resumes."""
    from taichi_star.batch import run as batch_run
    from taichi_star.batch.store import LOCK

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    folder = tmp_path / "run"
    with monkeypatch.context() as patch:
        patch.setattr(batch_run, "shows_progress", interrupted)
        with pytest.raises(KeyboardInterrupt):
            run(folder, params=PARAMS[:1])
    assert not (folder / LOCK).exists()
    assert len(run(folder, resume=True, params=PARAMS[:1])) == 1


@pytest.mark.parametrize("executor", ["class", "no_results"])
def test_an_executor_that_fails_as_it_starts_is_refused_or_lets_go_of_the_folder(tmp_path,
                                                                                 executor):
    """The class instead of an instance passed the "has a run" check, failed with a TypeError
    at the first chunk and left the run folder locked (an audit, 2026-12): refused before any
    folder is made; an executor whose run fails as it starts lets go of the folder."""
    from taichi_star.batch import InProcess

    class Broken:
        def run(self, tasks, progress=False):
            raise TypeError("fails as the run starts")  # a call, not a generator: at once

    folder = tmp_path / "run"
    if executor == "class":
        with pytest.raises(ValueError, match=r"^executor must be an Executor"):
            run_batch(PARAMS[:1], DURATION, solver=SOLVER, run_dir=folder, executor=InProcess)
        assert not folder.exists()
        return
    with pytest.raises(TypeError):
        run_batch(PARAMS[:1], DURATION, solver=SOLVER, run_dir=folder, executor=Broken())
    from taichi_star.batch.store import LOCK
    assert not (folder / LOCK).exists()
