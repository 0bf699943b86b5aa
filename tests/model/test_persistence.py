"""What a user saved stays whole and says what it is: a snapshot whose fields are of another
type (another precision, a damaged file) is refused, not cast; result files on a full disk or
in a missing folder fail naming the file, leaving the previous ones, and a CSV never keeps a
sidecar of another result; reading the provenance of a foreign or damaged file is a ValueError
naming it."""

import dataclasses
import errno
import json
import os
import re
from pathlib import Path
import stat

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star import provenance
from taichi_star.output import read_provenance

SOLVER = ts.SolverConfig(dt=5e-3)


@pytest.fixture(scope="module")
def simulator():
    sim = ts.Simulator([ts.StarParams(gait="none")], SOLVER)
    sim.fire(["A1"])
    sim.advance(0.02)
    return sim


@pytest.fixture(scope="module")
def results():
    """Two results of one robot's run (different gaits), each with records."""
    return [ts.simulate([ts.StarParams(gait=gait)], 0.02, SOLVER, record_interval_s=0.01)
            for gait in ("A1", "A1+A3")]


def test_a_snapshot_with_fields_of_another_type_is_refused_and_changes_nothing(simulator,
                                                                               tmp_path):
    """A state saved in f32 (every float field float32), or a damaged file whose positions are
    integers, was cast into this f64 engine and loaded as no run left it; it is refused naming
    the field, the state unchanged."""
    saved = simulator.save()
    before = simulator.save().fields
    single = dataclasses.replace(saved, fields={
        name: values.astype(np.float32) if values.dtype == np.float64 else values
        for name, values in saved.fields.items()})
    integers = dataclasses.replace(saved, fields={
        **saved.fields, "positions": saved.fields["positions"].astype(np.int64)})
    for snapshot, found in ((single, "float32"), (integers, "int64")):
        with pytest.raises(ValueError, match=rf"field '\w+' has type {found}, this engine "
                                             rf"float64 \(another precision, or a damaged"):
            simulator.load(snapshot.write(tmp_path / found))
        after = simulator.save().fields
        assert all(np.array_equal(after[name], before[name]) for name in before)


@pytest.mark.parametrize("field, value, message", [
    ("status", 5, r"'status' holds 5, not a status code in \[0, 4\]"),
    ("status", -1, r"'status' holds -1, not a status code in \[0, 4\]"),
    ("steps_done", -5, r"'steps_done' holds -5, not a count >= 0"),
    ("newton_total", -1, r"'newton_total' holds -1, not a count >= 0"),
    ("pending_count", 17, r"'pending_count' holds 17, more than the 16 firings a schedule holds"),
    ("time", -1e-3, r"'time' holds a time that is negative or not finite"),
    ("time", np.inf, r"'time' holds a time that is negative or not finite"),
])
def test_a_snapshot_with_values_no_run_holds_is_refused_and_changes_nothing(simulator, tmp_path,
                                                                             field, value,
                                                                             message):
    """A file whose numbers were changed (its shapes and types intact) loaded: an unknown
    status broke state(), a negative step count turned the robot's clock back, a pending count
    past the schedule's 16 let the kernel read past its firings (an audit, 2026-12). Each is
    refused naming the field, the state unchanged; the largest allowed values load (status 4,
    16 pending, t = 0)."""
    saved = simulator.save()
    before = saved.fields
    damaged = {**saved.fields, field: saved.fields[field].copy()}
    damaged[field][0] = value
    with pytest.raises(ValueError, match=message + r" \(a damaged file\)$"):
        simulator.load(dataclasses.replace(saved, fields=damaged))
    after = simulator.save().fields
    assert all(np.array_equal(after[name], before[name]) for name in before)


def test_a_snapshot_whose_robot_is_padding_or_whose_clock_left_its_steps_is_refused(simulator):
    """A robot's row marked "inactive" (the padding's status) and, with fixed steps, a time
    other than the step count times dt had loaded (an audit, 2026-12): each is refused naming
    the field, the state unchanged. The neighbours load: the last ulp's difference is refused
    too (the engine sets the time as exactly that product), and the statuses next to
    "inactive" ("non_finite", "step_limit") load."""
    from taichi_star.state import STATUS_INACTIVE

    saved = simulator.save()
    before = saved.fields
    steps = int(before["steps_done"][0])
    assert steps == 4 and before["time"][0] == steps * SOLVER.dt  # 0.02 s of 5-ms steps

    def edited(field, value):
        fields = {**before, field: before[field].copy()}
        fields[field][0] = value
        return dataclasses.replace(saved, fields=fields)

    for field, value, message in (
            ("status", STATUS_INACTIVE, r"'status' marks robot 0 'inactive', the status of a "
                                        r"batch's padding"),
            ("time", 0.025, r"'time' holds 0.025 s for row 0, not its 4 fixed steps of 0.005 s"),
            ("time", np.nextafter(0.02, 1.0), r"'time' holds 0.02\d* s for row 0, not its 4"),
            ("steps_done", 5, r"'time' holds 0.02 s for row 0, not its 5 fixed steps")):
        with pytest.raises(ValueError, match=message + r".* \(a damaged file\)$"):
            simulator.load(edited(field, value))
        after = simulator.save().fields
        assert all(np.array_equal(after[name], before[name]) for name in before)
    for status in (STATUS_INACTIVE - 1, STATUS_INACTIVE + 1):
        simulator.load(edited("status", status))
        assert simulator.save().fields["status"][0] == status
    simulator.load(saved)
    assert simulator.save().fields["status"][0] == before["status"][0]


def test_an_adaptive_snapshot_keeps_its_own_clock():
    """With adaptive steps the time is not the step count times dt: a saved state's own time
    loads (the fixed steps' rule above is not applied to it)."""
    sim = ts.Simulator([ts.StarParams(gait="A1")], ts.SolverConfig(adaptive=True))
    sim.advance(0.02)
    saved = sim.save()
    fields = saved.fields
    assert fields["time"][0] != fields["steps_done"][0] * sim.solver.dt
    sim.load(saved)
    np.testing.assert_array_equal(sim.save().fields["time"], fields["time"])


def test_a_snapshot_at_the_ends_of_its_values_loads():
    from taichi_star.actuation import PENDING_CAPACITY
    from taichi_star.state import STATUS_NAMES, check_saved_values

    sim = ts.Simulator([ts.StarParams(gait="none")], SOLVER)
    fields = dict(sim.save().fields)
    # a full schedule of firings of all eight actuators at one time (equal times are in order)
    for name, value in (("status", len(STATUS_NAMES) - 1), ("pending_count", PENDING_CAPACITY),
                        ("pending_actuators", 255), ("time", 0.0), ("steps_done", 0)):
        fields[name] = fields[name].copy()
        fields[name][:] = value
    check_saved_values(fields)


def test_a_snapshot_with_numbers_no_run_holds_is_refused():
    """A snapshot's real numbers are finite in every run (a failed step is undone to its start),
    its history flags 0 or 1, and each pending firing fires some actuators (a mask in [1, 255])
    in time order: a NaN position had loaded as "ok", a mask of -1 fired all eight actuators
    and a NaN firing time dropped its firing (an audit, 2026-12). Each is refused naming the
    field; the edges load (masks 1 and 255, two firings at one time, entries past the count
    holding anything)."""
    from taichi_star.state import check_saved_values

    fields = ts.Simulator([ts.StarParams(gait="none")], SOLVER).save().fields

    def changed(**values):
        """A copy of `fields` with instance 0's values set: None puts NaN in its first entry
        alone, a number fills its row."""
        copy = {name: array.copy() for name, array in fields.items()}
        for name, value in values.items():
            if value is None:
                copy[name][(0,) * copy[name].ndim] = np.nan
            else:
                copy[name][0] = value
        return copy

    for values, reason in (
            ({"positions": None}, "'positions' holds a value that is not finite"),
            ({"fire_time": None}, "'fire_time' holds a value that is not finite"),
            ({"history_valid": 7}, "'history_valid' holds a value other than 0 or 1"),
            ({"pending_count": 1, "pending_actuators": -1},
             "'pending_actuators' holds -1, not a set of actuators in [1, 255]"),
            ({"pending_count": 1, "pending_actuators": 256},
             "'pending_actuators' holds 256, not a set of actuators in [1, 255]"),
            ({"pending_count": 2, "pending_actuators": 1, "pending_due": [0.5, 0.2] + [0.0] * 14},
             "'pending_due' holds firings out of the order of their times")):
        with pytest.raises(ValueError, match=re.escape(f"saved state field {reason} (a damaged "
                                                       f"file)")):
            check_saved_values(changed(**values))
    edges = changed(pending_count=2, pending_due=[0.2, 0.2] + [0.0] * 14)
    edges["pending_actuators"][0, :2] = (1, 255)
    edges["pending_actuators"][0, 2:] = -7  # past the count: not a firing
    check_saved_values(edges)


def test_saving_to_a_non_path_is_a_value_error_naming_the_argument(simulator):
    with pytest.raises(ValueError, match="^path must be the path of the snapshot's .npz file, "
                                         "got int$"):
        simulator.save(42)


@pytest.mark.parametrize("write, what", [
    (lambda result: result.to_csv(42), "the CSV file"),
    (lambda result: result.to_parquet(42), "the Parquet file"),
    (lambda result: result.to_netcdf(42), "the netCDF file"),
    (lambda result: result.animate(42), "the .mp4 or .gif file"),
    (lambda result: read_provenance(42), "a result file")])
def test_a_result_file_that_is_not_a_path_is_a_value_error_naming_the_argument(results, write,
                                                                               what):
    with pytest.raises(ValueError, match=f"^path must be the path of {what}, got int$"):
        write(results[0])


@pytest.mark.parametrize("write, what", [
    (lambda result, path: result.to_csv(path), "the CSV file"),
    (lambda result, path: result.to_parquet(path), "the Parquet file"),
    (lambda result, path: result.to_netcdf(path), "the netCDF file"),
    (lambda result, path: result.animate(path), "the .mp4 or .gif file")])
@pytest.mark.parametrize("path", ["", ".", Path("/")])
def test_a_result_file_path_that_names_no_file_is_a_value_error_naming_the_argument(
        results, tmp_path, monkeypatch, write, what, path):
    """"" was pathlib's "PosixPath('.') has an empty name" (an audit); a path naming a file
    is written (the other side of the boundary)."""
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ValueError, match=rf"^path must be the path of {re.escape(what)}, got "
                                         rf"'{re.escape(os.fspath(path))}', which names no "
                                         rf"file$"):
        write(results[0], path)
    assert list(tmp_path.iterdir()) == []
    if what != "the .mp4 or .gif file":  # a movie needs shapes; its path is checked first
        assert write(results[0], "r.file") == Path("r.file")


def strict_json(text: str):
    """`text` as JSON, refusing NaN and Infinity (Python's json reads them; JSON has none)."""
    def refuse(constant):
        raise ValueError(f"not JSON: {constant}")
    return json.loads(text, parse_constant=refuse)


def test_provenance_of_a_run_of_no_time_is_json_with_null_rates(results, tmp_path):
    """robot_steps_per_s is NaN for a run of no measurable time: the sidecar, the Parquet
    metadata and the netCDF attribute held `NaN`, which JSON readers refuse (an audit)."""
    import pyarrow.parquet as pq
    import xarray as xr

    result = dataclasses.replace(results[0],
                                 timing=dataclasses.replace(results[0].timing, run_s=0.0))
    write_all(result, tmp_path)
    with xr.open_dataset(tmp_path / "r.nc") as dataset:
        netcdf = dataset.attrs["provenance"]
    texts = {"csv": (tmp_path / "r.csv.json").read_text(), "netcdf": netcdf,
             "parquet": pq.read_schema(tmp_path / "r.parquet").metadata[b"taichi_star"].decode()}
    for kind, text in texts.items():
        facts = strict_json(text)
        assert facts["timing"]["robot_steps_per_s"] is None, kind
        assert facts["timing"]["robot_steps"] == result.timing.robot_steps, kind
    # a run of measurable time keeps its number
    write_all(results[0], tmp_path)
    facts = strict_json((tmp_path / "r.csv.json").read_text())
    assert facts["timing"]["robot_steps_per_s"] == results[0].timing.robot_steps_per_s > 0


def test_finite_json_writes_null_for_every_non_finite_number_and_refuses_what_is_left():
    facts = {"a": float("nan"), "b": [1.5, float("inf"), (-float("inf"), 2)], "c": "NaN",
             "d": np.float64("nan"), "e": 3}
    assert json.loads(provenance.provenance_json(facts)) == {
        "a": None, "b": [1.5, None, [None, 2]], "c": "NaN", "d": None, "e": 3}
    # allow_nan=False: a NaN that gets past finite_json (here through `default`) is an error
    with pytest.raises(ValueError, match="Out of range float values are not JSON compliant"):
        provenance.provenance_json({"a": object()}, default=lambda value: float("nan"))


def test_library_result_files_record_the_machine_and_the_arch(results, tmp_path):
    """Only the studies' sidecars recorded the machine, and no file the arch (the result did
    not keep it: an audit); both are in every file's provenance now."""
    import xarray as xr

    assert results[0].arch == "cpu"
    write_all(results[0], tmp_path)
    machine = provenance.machine()
    for name in ("r.csv", "r.parquet", "r.nc"):
        facts = read_provenance(tmp_path / name)
        assert facts["arch"] == "cpu" and facts["machine"] == machine, name
    assert set(machine) == {"cpu_model", "cores", "vector_extensions", "caches", "gpus",
                            "platform"}
    with xr.open_dataset(tmp_path / "r.nc") as dataset:
        assert dataset.attrs["arch"] == "cpu"
    unknown = dataclasses.replace(results[0], arch=None)  # a result built by hand
    assert read_provenance(unknown.to_csv(tmp_path / "u.csv"))["arch"] is None


def write_all(result, folder):
    result.to_csv(folder / "r.csv")
    result.to_parquet(folder / "r.parquet")
    result.to_netcdf(folder / "r.nc")


def test_result_files_on_a_full_disk_or_in_a_missing_folder_name_the_file(results, tmp_path,
                                                                           full_disk):
    """A full disk leaves the previous files byte for byte and nothing beside them; both it and
    a missing folder are OSErrors naming the file asked for (they named no file, or the
    temporary or scratch folder beside it)."""
    first, second = results
    write_all(first, tmp_path)
    written = {path.name: path.read_bytes() for path in tmp_path.iterdir()}
    with full_disk():
        for name, write in (("r.csv", second.to_csv), ("r.parquet", second.to_parquet),
                            ("r.nc", second.to_netcdf)):
            with pytest.raises(OSError, match=rf"^cannot write {name} \(No space left"):
                write(tmp_path / name)
    assert {path.name: path.read_bytes() for path in tmp_path.iterdir()} == written
    missing = tmp_path / "missing"
    for name, write in (("r.csv", second.to_csv), ("r.parquet", second.to_parquet),
                        ("r.nc", second.to_netcdf), ("r.gif", second.animate)):
        with pytest.raises(OSError, match=rf"^cannot write {name}: its folder "
                                          rf"{re.escape(str(missing))} does not exist$"):
            write(missing / name)
    assert not missing.exists()  # animate made it until 2026-12
    (tmp_path / "a_file").write_text("")
    with pytest.raises(OSError, match=r"^cannot write r.csv: its folder .*a_file is not a folder$"):
        second.to_csv(tmp_path / "a_file" / "r.csv")


def test_a_parquet_file_over_a_csv_takes_its_sidecar_away_whole_or_not_at_all(results, tmp_path,
                                                                             monkeypatch):
    """A Parquet file written over a CSV's name removes the CSV's sidecar (it describes a table
    no longer there) by the pair's own steps: the sidecar moved aside, the file renamed into
    place, the moved sidecar then deleted. A failed rename puts the sidecar back beside the
    CSV still there, a rename done leaves the Parquet file alone."""
    pytest.importorskip("pyarrow")
    first, second = results
    path = first.to_csv(tmp_path / "r.data")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    replace = provenance.os.replace

    def failing_rename(source, target):
        if Path(target).name == "r.data":
            raise OSError(errno.EIO, "Input/output error")
        replace(source, target)
    monkeypatch.setattr(provenance.os, "replace", failing_rename)
    with pytest.raises(OSError, match=r"^cannot write r.data \(Input/output error\)$"):
        second.to_parquet(path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    monkeypatch.setattr(provenance.os, "replace", replace)
    second.to_parquet(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.data"]
    assert read_provenance(path)["parameters"]["gait"] == "A1+A3"  # the second run's


def test_a_csv_and_its_sidecar_are_replaced_as_a_pair(results, tmp_path, monkeypatch):
    """The table was renamed into place before its provenance was even made, and a kill
    between the two left the new table beside the previous run's sidecar (an audit: a CSV of
    alpha 0.9 whose provenance said 0.8). Now both are written to temporary files first: a
    full disk at the sidecar leaves the previous pair; a failure (or a kill) after the table's
    rename leaves the new table without a sidecar, so that reading its provenance fails
    instead of telling another run's; a failed table rename puts the previous sidecar back."""
    first, second = results
    path = first.to_csv(tmp_path / "r.csv")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    fsync, replace = provenance.os.fsync, provenance.os.replace
    writes = []

    def full_at_the_second_file(descriptor):
        if not stat.S_ISDIR(os.fstat(descriptor).st_mode):  # files, not their folder's sync
            writes.append(descriptor)
        if len(writes) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        fsync(descriptor)
    monkeypatch.setattr(provenance.os, "fsync", full_at_the_second_file)
    with pytest.raises(OSError, match=r"^cannot write r.csv.json \(No space left"):
        second.to_csv(path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    monkeypatch.setattr(provenance.os, "fsync", fsync)

    def failing_rename_into(name, error=OSError(errno.EIO, "Input/output error")):
        def rename(source, target):
            if Path(target).name == name:
                raise error
            replace(source, target)
        return rename
    monkeypatch.setattr(provenance.os, "replace", failing_rename_into("r.csv"))
    with pytest.raises(OSError, match=r"^cannot write r.csv \(Input/output error\)$"):
        second.to_csv(path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    # Ctrl-C there too (the sidecar moved aside was deleted, an audit)
    monkeypatch.setattr(provenance.os, "replace",
                        failing_rename_into("r.csv", KeyboardInterrupt()))
    with pytest.raises(KeyboardInterrupt):
        second.to_csv(path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before

    def interrupted_after_renaming_into(name):
        """Python raises Ctrl-C after the system call in progress returns: the rename done."""
        def rename(source, target):
            replace(source, target)
            if Path(target).name == name:
                raise KeyboardInterrupt
        return rename
    # after the old sidecar was moved aside: put back, the previous pair as it was
    moved = next(p.name for p in tmp_path.iterdir() if p.name.endswith(".json"))
    monkeypatch.setattr(provenance.os, "replace", lambda source, target: (
        interrupted_after_renaming_into(Path(target).name)(source, target)
        if Path(source).name == moved else replace(source, target)))
    with pytest.raises(KeyboardInterrupt):
        second.to_csv(path)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    # after the table's rename: the new table, without a sidecar (it stood beside the previous
    # one's, a second audit)
    monkeypatch.setattr(provenance.os, "replace", interrupted_after_renaming_into("r.csv"))
    with pytest.raises(KeyboardInterrupt):
        second.to_csv(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]
    monkeypatch.setattr(provenance.os, "replace", replace)
    first.to_csv(path)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    monkeypatch.setattr(provenance.os, "replace", failing_rename_into("r.csv.json"))
    with pytest.raises(OSError, match=r"^cannot write r.csv.json \(Input/output error\)$"):
        second.to_csv(path)
    pd.testing.assert_frame_equal(pd.read_csv(path), second.summary.reset_index(drop=True),
                                  check_dtype=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.csv"]
    with pytest.raises(ValueError, match=r"r.csv: no taichi_star provenance beside it"):
        read_provenance(path)
    # a folder where the sidecar goes: refused before the table changes
    monkeypatch.setattr(provenance.os, "replace", replace)
    first.to_csv(path)
    (tmp_path / "r.csv.json").unlink()
    (tmp_path / "r.csv.json").mkdir()
    table = path.read_bytes()
    with pytest.raises(OSError, match=r"^cannot write r.csv.json \(Is a directory\)$"):
        second.to_csv(path)
    assert path.read_bytes() == table


def test_a_csv_changed_since_it_was_written_is_not_vouched_for(results, tmp_path):
    """The sidecar records the table's rows and SHA-256: a truncated, flipped or edited CSV
    read back other numbers with its provenance read as if it described them (an audit: 140 of
    150 single-bit flips); `read_provenance` now refuses it, naming the file."""
    path = results[0].to_csv(tmp_path / "r.csv")
    facts = read_provenance(path)
    assert facts["table_rows"] == 1
    data = path.read_bytes()
    for damaged in (data[:-1], data.replace(b",", b";", 1), data + b"\n"):
        path.write_bytes(damaged)
        with pytest.raises(ValueError, match=rf"^{re.escape(str(path))}: not the table its "
                                             r"provenance r.csv.json describes"):
            read_provenance(path)
    path.write_bytes(data)
    assert read_provenance(path) == facts
    # a sidecar without the stamp (written before tables were stamped, or by hand) has nothing
    # to check the table against: it is read as it is, not refused
    unstamped = {key: value for key, value in facts.items()
                 if key not in provenance.table_stamp(0, b"")}
    assert len(unstamped) == len(facts) - 2
    (tmp_path / "r.csv.json").write_text(json.dumps(unstamped))
    assert read_provenance(path) == unstamped


def test_the_provenance_of_a_damaged_or_foreign_file_is_a_value_error_naming_it(results,
                                                                                tmp_path):
    """pyarrow's ArrowInvalid, a KeyError of the metadata key, xarray's backend message, a
    bare JSONDecodeError and, for a truncated netCDF file, an OSError of error number -101
    ("NetCDF: HDF error", an audit) were what these raised."""
    whole = results[0].to_netcdf(tmp_path / "whole.nc").read_bytes()
    (tmp_path / "truncated.nc").write_bytes(whole[:len(whole) // 2])
    (tmp_path / "garbage.parquet").write_bytes(b"garbage")
    pd.DataFrame({"a": [1]}).to_parquet(tmp_path / "foreign.parquet")
    (tmp_path / "garbage.nc").write_bytes(b"garbage")
    (tmp_path / "r.csv").write_text("a\n1\n")
    (tmp_path / "r.csv.json").write_text('{"taichi_star_version": ')
    for name, source in (("garbage.parquet", "garbage.parquet"),
                         ("foreign.parquet", "foreign.parquet"), ("garbage.nc", "garbage.nc"),
                         ("truncated.nc", "truncated.nc"), ("r.csv", "r.csv.json")):
        with pytest.raises(ValueError, match=rf"{source}: no taichi_star provenance in it \("):
            read_provenance(tmp_path / name)
    # a plain CSV, readable but with no sidecar, holds no provenance as a plain Parquet file
    # does (it raised FileNotFoundError for the sidecar: an audit, 2026-12); a CSV that is not
    # there cannot be read (an OSError still)
    (tmp_path / "plain.csv").write_text("a\n1\n")
    with pytest.raises(ValueError, match=r"plain.csv: no taichi_star provenance beside it \(no "
                                         r"sidecar plain.csv.json: not written by to_csv\)"):
        read_provenance(tmp_path / "plain.csv")
    with pytest.raises(OSError):
        read_provenance(tmp_path / "absent.csv")


@pytest.mark.parametrize("suffix", [".gz", ".bz2", ".xz", ".zip", ".GZ"])  # pandas: any case
def test_a_csv_named_compressed_is_compressed_as_pandas_reads_it(results, tmp_path, suffix):
    """"run.csv.gz" held plain text, which pandas' read_csv (choosing the compression by the
    suffix, as its to_csv does) refused as a damaged gzip file (an audit, 2026-12). The table
    reads back exactly, the sidecar vouches for the compressed bytes, and the same table gives
    the same bytes (a gzip stream's time stamp is 0)."""
    plain = results[1].to_csv(tmp_path / "r.csv")
    path = results[1].to_csv(tmp_path / f"r.csv{suffix}")
    assert path.read_bytes() != plain.read_bytes()
    pd.testing.assert_frame_equal(pd.read_csv(path), pd.read_csv(plain))
    facts = read_provenance(path)
    assert facts["table_sha256"] == provenance.table_stamp(0, path.read_bytes())["table_sha256"]
    again = path.read_bytes()
    results[1].to_csv(path)
    assert path.read_bytes() == again


def test_a_csv_named_in_a_compression_to_csv_does_not_write_is_refused(results, tmp_path):
    """pandas' other suffixes (.zst, .tar, a tar archive compressed) are refused before
    anything is written, naming the path and the suffixes written."""
    for name in ("r.csv.zst", "r.csv.tar", "r.csv.tar.gz", "R.TAR.XZ"):
        with pytest.raises(ValueError, match=rf"path '.*{re.escape(name)}': to_csv writes plain "
                                             rf"CSV or CSV compressed as .gz, .bz2, .xz, .zip "
                                             rf"say"):
            results[0].to_csv(tmp_path / name)
        assert not list(tmp_path.iterdir())


def test_a_snapshot_file_records_its_code_and_a_load_by_other_code_warns(simulator, tmp_path):
    """A snapshot written to a file records the code that wrote it, as every result file
    does; `load` compares it with its own code and warns where it differs (a continuation is
    bit for bit only with the same code), naming what differs; a snapshot kept in memory
    records none and loads silently (an audit, 2026-12: the files recorded no code)."""
    import warnings

    from taichi_star.simulator import SNAPSHOT_CODE_KEYS, SimulatorSnapshot

    path = simulator.save(tmp_path / "state.npz")
    saved = SimulatorSnapshot.read(path)
    own = provenance.code_record()
    assert {key: saved.code.get(key) for key in SNAPSHOT_CODE_KEYS} == \
        {key: own.get(key) for key in SNAPSHOT_CODE_KEYS}
    assert saved.code["taichi_star_version"] == ts.__version__ and saved.code["date"]
    in_memory = simulator.save()
    assert in_memory.code == {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulator.load(path)
        simulator.load(in_memory)
        simulator.load(dataclasses.replace(saved, code={}))  # written before it was recorded
    for key in SNAPSHOT_CODE_KEYS:
        other = dataclasses.replace(saved, code={**saved.code, key: "0other"})
        with pytest.warns(RuntimeWarning, match=rf"written by other code \({key} 0other there, "
                                                rf".* here; written "
                                                rf"{re.escape(saved.code['date'])}\)"):
            simulator.load(other)
    assert simulator.save().fields.keys() == in_memory.fields.keys()
    assert all(np.array_equal(simulator.save().fields[name], values)
               for name, values in in_memory.fields.items())
