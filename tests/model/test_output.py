"""Result files (CSV, Parquet, netCDF: values, parameters and provenance back), labelled data
(xarray), animation and the quiet import."""

import dataclasses
import json
import os
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.output import column_unit, summary_of_dataset


# the second robot's actuator profile is not the default: the files must carry it, not a name
CHANGED_PROFILE = ts.CurvatureProfile(heating=(-89.5, 62.724, 0.061, 104.04), switch_time=0.15)
RECORDED_PARAMS = [ts.StarParams(gait="A1+A2"),
                   ts.StarParams(gait="A3", alpha=0.5, actuator_profile=CHANGED_PROFILE)]


@pytest.fixture(scope="module")
def recorded():
    return ts.simulate(RECORDED_PARAMS, 0.2, ts.SolverConfig(dt=2e-3), record_interval_s=0.04,
                       record_shapes=True)


def test_a_summary_row_gives_its_parameters_back_also_from_a_csv(recorded, tmp_path):
    """StarParams.from_row reads the unit-suffixed columns of a summary row (in memory, and
    read back from a plain pandas CSV, the actuator profile as text); an unreadable profile
    text and a missing column are named."""
    for index, params in enumerate(RECORDED_PARAMS):
        assert ts.StarParams.from_row(recorded.summary.iloc[index]) == params
    assert recorded.summary["actuator_profile"].map(type).eq(str).all()
    path = tmp_path / "summary.csv"
    recorded.summary.to_csv(path, index=False)
    table = pd.read_csv(path)
    assert [ts.StarParams.from_row(row) for _, row in table.iterrows()] == RECORDED_PARAMS
    assert ts.StarParams.from_row(table.iloc[1], alpha=0.9) == RECORDED_PARAMS[1].replace(alpha=0.9)
    changed = table.iloc[0].copy()
    changed["actuator_profile"] = "CurvatureProfile(heating=(1, 2, 3, 4), ...)"
    with pytest.raises(ValueError, match="actuator_profile"):
        ts.StarParams.from_row(changed)
    profile = RECORDED_PARAMS[0].actuator_profile
    assert ts.StarParams.from_row(changed, actuator_profile=profile) == RECORDED_PARAMS[0]
    with pytest.raises(ValueError, match="period_s"):
        ts.StarParams.from_row(table.iloc[0].drop("period_s"))


def assert_same_summary(back: pd.DataFrame, summary: pd.DataFrame):
    """Every column's values equal (NaN where NaN), the parameters recovered row by row."""
    assert list(back.columns) == list(summary.columns)
    for column in summary.columns:
        np.testing.assert_array_equal(back[column].to_numpy(), summary[column].to_numpy(),
                                      err_msg=column)
    assert [ts.StarParams.from_row(row) for _, row in back.iterrows()] == RECORDED_PARAMS


def test_csv_parquet_and_netcdf_round_trip_with_the_same_provenance(recorded, tmp_path):
    import xarray as xr

    from taichi_star.output import read_provenance, summary_of_dataset

    summary = recorded.summary
    plain = tmp_path / "plain.parquet"
    summary.to_parquet(plain)  # plain pandas: every column has an Arrow type
    assert_same_summary(pd.read_parquet(plain), summary)
    csv = recorded.to_csv(tmp_path / "summary.csv")
    assert_same_summary(pd.read_csv(csv), summary)
    parquet = recorded.to_parquet(tmp_path / "summary.parquet")
    assert_same_summary(pd.read_parquet(parquet), summary)
    netcdf = recorded.to_netcdf(tmp_path / "result.nc")
    with xr.open_dataset(netcdf) as dataset:
        back = summary_of_dataset(dataset)
    assert_same_summary(back[summary.columns], summary)
    trajectory = recorded.to_parquet(tmp_path / "trajectory.parquet", table="trajectory")
    pd.testing.assert_frame_equal(pd.read_parquet(trajectory), recorded.trajectory)
    # the units of the table written (the summary's were, 2026-12)
    assert read_provenance(trajectory)["units"] == {"t_s": "s", "x_mm": "mm", "y_mm": "mm",
                                                    "heading_deg": "degree"}
    facts = [read_provenance(path) for path in (csv, parquet, netcdf)]
    for fact in facts:
        for key in ("taichi_star_version", "git_commit", "git_dirty", "solver", "parameters",
                    "varying_parameters", "timing", "arguments"):
            assert fact[key] == facts[0][key], key
    # the call's own arguments, which no column holds (the steady speeds' first cycle, the
    # records: an audit, 2026-12, found none of them in the files)
    assert facts[0]["arguments"] == {
        "function": "simulate", "duration_s": 0.2, "cycles": None, "record_interval_s": 0.04,
        "record_shapes": True, "steady_from_cycle": 1, "sensitivities": [], "chunk_size": None}
    assert facts[0]["timing"] == {**dataclasses.asdict(recorded.timing),
                                  "robot_steps_per_s": recorded.timing.robot_steps_per_s}
    assert facts[0]["taichi_star_version"] == ts.__version__
    assert facts[0]["solver"]["dt"] == 2e-3 and facts[0]["solver"]["integrator"] == "euler"
    assert facts[0]["parameters"]["youngs_modulus"] == 5e6  # equal in both robots
    # an integer parameter stays an integer in every file (it came back as the text '18' with
    # NumPy's integer left unconverted: a mutation audit, 2026-12)
    for fact in facts:
        assert type(fact["parameters"]["n_arc"]) is int and fact["parameters"]["n_arc"] == 18
    # a result that more than one code version made says which made which chunks
    versions = [{"code": {"version": "0.0.1"}, "chunks": [0]},
                {"code": {"version": ts.__version__}, "chunks": [1]}]
    mixed = dataclasses.replace(recorded, code_versions=versions)
    for write, name in ((mixed.to_csv, "mixed.csv"), (mixed.to_parquet, "mixed.parquet"),
                        (mixed.to_netcdf, "mixed.nc")):
        assert read_provenance(write(tmp_path / name))["code_versions"] == versions, name
    assert set(facts[0]["varying_parameters"]) == {"gait", "alpha", "actuator_profile"}
    assert json.loads(json.dumps(facts[0])) == facts[0]  # plain JSON values
    with pytest.raises(ValueError, match="table"):
        recorded.to_parquet(tmp_path / "x.parquet", table="shapes")
    with pytest.raises(ValueError, match="table 'sensitivities': this result has none"):
        recorded.to_parquet(tmp_path / "x.parquet", table="sensitivities")
    # any name: the provenance is read by the file's content ("x.pq" was taken for a CSV)
    renamed = {tmp_path / "summary.pq": parquet, tmp_path / "result.nc4": netcdf}
    for name, written in renamed.items():
        name.write_bytes(written.read_bytes())
        assert read_provenance(name)["parameters"] == facts[0]["parameters"]
    # a CSV under a Parquet or netCDF name is read as the CSV its sidecar describes (it was
    # taken for a damaged Parquet or netCDF file: an audit, 2026-12)
    for name in ("table.parquet", "table.nc"):
        written = recorded.to_csv(tmp_path / name)
        assert read_provenance(written)["parameters"] == facts[0]["parameters"]
    # and a Parquet or netCDF file written over such a CSV takes its sidecar away (it stayed,
    # describing a table no longer there); a JSON file of another kind beside one is left
    recorded.to_parquet(tmp_path / "table.parquet")
    recorded.to_netcdf(tmp_path / "table.nc")
    assert not (tmp_path / "table.parquet.json").exists()
    assert not (tmp_path / "table.nc.json").exists()
    assert read_provenance(tmp_path / "table.parquet")["parameters"] == facts[0]["parameters"]
    (tmp_path / "notes.parquet.json").write_text('{"mine": true}')
    recorded.to_parquet(tmp_path / "notes.parquet")
    assert json.loads((tmp_path / "notes.parquet.json").read_text()) == {"mine": True}


def test_xarray_holds_the_tables_with_units_and_survives_netcdf(recorded, tmp_path):
    import xarray as xr

    dataset = recorded.to_xarray()
    assert dataset.sizes == {"instance": 2, "time": 6, "node": 193, "xy": 2}
    np.testing.assert_array_equal(dataset.speed_mm_s, recorded.summary.speed_mm_s)
    np.testing.assert_array_equal(dataset.alpha, [0.8, 0.5])
    assert dataset.speed_mm_s.attrs["units"] == "mm/s"
    assert dataset.youngs_modulus_pa.attrs["units"] == "Pa"
    # the shapes in metres, the parameters as coordinates, and how the run was made (each
    # could be dropped or mislabelled unseen: a mutation audit, 2026-12)
    assert dataset.positions.attrs["units"] == "m"
    assert "alpha" in dataset.coords and "speed_mm_s" in dataset.data_vars
    assert (dataset.attrs["dt_s"], dataset.attrs["adaptive"], dataset.attrs["precision"]) == (
        2e-3, 0, "f64")
    assert "git_commit" in dataset.attrs and "git_dirty" in dataset.attrs
    last = recorded.trajectory[recorded.trajectory.t_s == recorded.trajectory.t_s.max()]
    np.testing.assert_array_equal(dataset.centroid_x_mm.isel(time=-1), last.x_mm)
    np.testing.assert_array_equal(dataset.positions, recorded.shapes)
    path = recorded.to_netcdf(tmp_path / "result.nc")
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back.positions, recorded.shapes)
        assert list(back.gait.values) == ["A1+A2", "A3"]


def test_every_netcdf_variable_and_coordinate_has_units_one_for_pure_numbers(recorded, tmp_path):
    """The docstring promises a `units` attribute on every variable: the coordinates instance,
    node and xy had none, and pure numbers had "" where the project writes "1"; text (gait,
    status, the xy labels) has no unit, ""."""
    import xarray as xr

    with xr.open_dataset(recorded.to_netcdf(tmp_path / "result.nc")) as back:
        units = {name: back[name].attrs.get("units") for name in [*back.coords, *back.data_vars]}
    assert None not in units.values(), [name for name, unit in units.items() if unit is None]
    assert {name: units[name] for name in ("instance", "node", "xy", "time", "steps",
                                           "shape_sane", "alpha", "n_arc", "gait", "status",
                                           "speed_mm_s")} == {
        "instance": "1", "node": "1", "xy": "", "time": "s", "steps": "1", "shape_sane": "1",
        "alpha": "1", "n_arc": "1", "gait": "", "status": "", "speed_mm_s": "mm/s"}


def test_a_row_of_an_xarray_dataset_gives_its_parameters_back(recorded, tmp_path):
    """`dataset.isel(instance=i)` (of `to_xarray`, or read from netCDF) holds 0-d arrays:
    `StarParams.from_row` failed on them with a confusing message (an audit)."""
    import xarray as xr

    dataset = recorded.to_xarray()
    assert [ts.StarParams.from_row(dataset.isel(instance=i)) for i in (0, 1)] == RECORDED_PARAMS
    with xr.open_dataset(recorded.to_netcdf(tmp_path / "result.nc")) as back:
        assert ts.StarParams.from_row(back.isel(instance=1), alpha=0.3) == \
            RECORDED_PARAMS[1].replace(alpha=0.3)


def test_sensitivities_go_to_xarray_and_netcdf_beside_the_summary_not_into_it(tmp_path):
    """to_xarray left the sensitivities out without a word, though to_csv and to_parquet write
    them (an audit, 2026-12): each column is a variable (netCDF names hold no "/"), per
    instance or per record, with its units and its column's name; the summary read back is
    the run's without them."""
    import xarray as xr

    result = ts.simulate([ts.StarParams(), ts.StarParams(gait="A1+A2")], 0.02,
                         record_interval_s=0.01, sensitivities=("alpha", "actuator_gains[1]"))
    path = result.to_netcdf(tmp_path / "sensitive.nc")
    with xr.open_dataset(path) as back:
        speed = back["d_displacement_x_mm__d_alpha"]
        np.testing.assert_array_equal(speed, result.sensitivity("displacement_x_mm", "alpha"))
        assert speed.attrs["units"] == column_unit("d(displacement_x_mm)/d(alpha)")
        assert speed.attrs["column"] == "d(displacement_x_mm)/d(alpha)"
        path_derivative = back["d_centroid_y_mm__d_actuator_gains_1"]
        assert path_derivative.dims == ("instance", "time")
        np.testing.assert_array_equal(path_derivative, result.sensitivity(
            "y_mm", "actuator_gains[1]"))
        # the summary's heading and the records' share a column name, d(heading_deg)/d(alpha),
        # in the two tables: each its own variable (the records' overwrote the summary's until
        # 2026-12, an audit), every column of both tables there once
        turn = back["d_heading_deg__d_alpha"]
        assert turn.dims == ("instance",)
        np.testing.assert_array_equal(turn, result.sensitivity("heading_deg", "alpha"))
        np.testing.assert_array_equal(back["d_record_heading_deg__d_alpha"], result.sensitivity(
            "heading_deg", "alpha", trajectory=True))
        columns = [back[name].attrs["column"] for name in back.data_vars
                   if back[name].attrs.get("sensitivity")]
        assert sorted(columns) == sorted([*result.sensitivities.columns,
                                          *result.trajectory_sensitivities.columns.drop(
                                              ["instance", "t_s"])])
        summary = summary_of_dataset(back)
        assert list(summary.columns) == list(result.summary.columns)
        np.testing.assert_array_equal(summary.speed_mm_s, result.summary.speed_mm_s)


def test_sensitivities_written_in_run_order_and_no_path_derivatives_without_records(tmp_path):
    """The sensitivities table names no instance: to_csv and to_parquet write it in the run's
    order after a user's sort in place (the sorted rows went out, each instance another's
    derivative beside the summary: an audit, 2026-12). A run without records has no
    derivatives of the path: a ValueError saying so (an empty array before)."""
    result = ts.simulate([ts.StarParams(), ts.StarParams(gait="A1+A2")], 0.02,
                         sensitivities=("alpha",))
    column = "d(displacement_x_mm)/d(alpha)"
    expected = result.sensitivity("displacement_x_mm", "alpha")
    assert expected[0] != expected[1]  # an order that shows
    # what a sort in place leaves (pandas deprecates inplace=): the rows reordered, their labels
    # kept
    result.sensitivities = result.sensitivities.sort_index(ascending=False)
    back = pd.read_csv(result.to_csv(tmp_path / "sensitivities.csv", table="sensitivities"))
    np.testing.assert_array_equal(back[column], expected)
    stored = pd.read_parquet(result.to_parquet(tmp_path / "sensitivities.parquet",
                                               table="sensitivities"))
    np.testing.assert_array_equal(stored[column], expected)
    for output, trajectory in (("x_mm", False), ("heading_deg", True)):
        with pytest.raises(ValueError, match=rf"^output '{output}': this run recorded no "
                                             rf"trajectory \(simulate with record_interval_s > "
                                             rf"0 for it\)$"):
            result.sensitivity(output, "alpha", trajectory=trajectory)


def test_a_batchs_result_goes_to_xarray_by_its_instance_column(recorded, tmp_path):
    """`run_batch` names its instances in a summary column: that is the coordinate (it also
    was a variable, and xarray refused the dataset), and an instance without records (a
    resumed batch's stored chunks carry their summaries alone) gets NaN rows, not another
    instance's."""
    import xarray as xr

    from taichi_star.batch import run_batch

    batch = run_batch(RECORDED_PARAMS, 0.2, solver=ts.SolverConfig(dt=2e-3),
                      record_interval_s=0.04, chunk_size=1)
    dataset = batch.to_xarray()
    assert "instance" not in dataset.data_vars
    np.testing.assert_array_equal(dataset.instance, [0, 1])
    plain = recorded.to_xarray()
    for name in ("centroid_x_mm", "record_heading_deg", "speed_mm_s", "alpha"):
        np.testing.assert_array_equal(dataset[name], plain[name])
    with xr.open_dataset(batch.to_netcdf(tmp_path / "batch.nc")) as back:
        np.testing.assert_array_equal(back.centroid_y_mm, plain.centroid_y_mm)
        # the batch's summary back with its instance column first (it was dropped: an audit),
        # a plain result's without one
        table = summary_of_dataset(back)
    assert list(table.columns[:2]) == list(batch.summary.columns[:2])
    np.testing.assert_array_equal(table.instance, batch.summary.instance)
    assert "instance" not in summary_of_dataset(plain).columns
    # a selection keeps its instances: the plain one's in the index, as simulate's summary
    # numbers its rows (they were renumbered 0, 1, ...: an audit, 2026-12), the batch's in
    # its column
    picked = summary_of_dataset(plain.isel(instance=[1]))
    assert picked.index.tolist() == [1]
    pd.testing.assert_frame_equal(picked, recorded.summary.iloc[[1]][picked.columns],
                                  check_exact=True, check_dtype=False)
    assert summary_of_dataset(dataset.isel(instance=[1]))["instance"].tolist() == [1]
    first_only = dataclasses.replace(batch, trajectory=batch.trajectory[
        batch.trajectory.instance == 0])
    partial = first_only.to_xarray()
    np.testing.assert_array_equal(partial.centroid_x_mm.sel(instance=0),
                                  plain.centroid_x_mm.sel(instance=0))
    assert np.isnan(partial.centroid_x_mm.sel(instance=1)).all()


def test_a_batchs_files_record_its_call_and_an_off_grid_duration_is_told_once(tmp_path):
    """run_batch's arguments in its files (cycles or duration_s as given, the chunks), and a
    duration_s off the step grid told in one warning for the batch, not one per chunk (its
    chunks are `simulate` calls, each of which would tell it); cycles off the grid too, naming
    the cycles and the first instance they put off it (rounded silently until 2026-12: a
    "cycle" of a period of 3.1505 s at 1-ms steps simulated 3.15 s, an audit)."""
    import warnings

    from taichi_star.batch import run_batch
    from taichi_star.output import read_provenance

    solver = ts.SolverConfig(dt=2e-3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        batch = run_batch(RECORDED_PARAMS, 0.0051, solver=solver, chunk_size=1)
    assert [str(warning.message) for warning in caught] == [
        "duration_s = 0.0051 s is not a whole number of steps (dt = 0.002 s): 3 steps, "
        "0.006 s, are simulated (timegrid.nearest_interval gives a duration on the grid)"]
    assert batch.summary["duration_s"].tolist() == [0.006, 0.006]
    # the speed over the time simulated, as simulate records it
    assert batch.summary["speed_mm_s"].to_numpy() == pytest.approx(np.hypot(
        batch.summary["displacement_x_mm"], batch.summary["displacement_y_mm"]) / 0.006,
        rel=1e-12)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert ts.simulate(RECORDED_PARAMS, 0.0051, solver).arguments["duration_s"] == 0.006
    assert read_provenance(batch.to_csv(tmp_path / "batch.csv"))["arguments"] == {
        "function": "run_batch", "duration_s": 0.0051, "cycles": None, "record_interval_s": 0.0,
        "record_shapes": False, "steady_from_cycle": 1, "sensitivities": [], "chunk_size": 1}
    short = [params.replace(period=0.3337) for params in RECORDED_PARAMS]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cycled = run_batch(short, cycles=0.02, solver=solver)
    assert [str(warning.message) for warning in caught] == [
        "cycles = 0.02 periods of params[0], 0.006674 s, is not a whole number of steps "
        "(dt = 0.002 s): 3 steps, 0.006 s, are simulated (each instance's duration_s in the "
        "summary)"]
    assert cycled.summary["duration_s"].tolist() == [0.006, 0.006]  # 0.006674 s rounded
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run_batch(short, cycles=1.0 / 0.3337 * 0.006, solver=solver)  # 0.006 s, 3 steps
    assert caught == []
    assert cycled.arguments["cycles"] == 0.02 and cycled.arguments["duration_s"] is None


def test_a_period_off_the_step_grid_is_told_once_with_its_nan_steady_speeds():
    """With fixed steps a period that is not a whole number of steps has its cycles begin
    between steps, where no centroid is taken: its steady speeds are NaN. They were NaN with
    status ok and no word (an audit); now one warning per call or batch names them, and a
    robot whose period is whole steps beside it keeps its steady speed."""
    import warnings

    from taichi_star.batch import run_batch

    coarse = ts.StarParams(gait="A1+A2", n_arc=6, n_limb=2, period=0.1635)
    batch = [coarse, coarse.replace(period=0.1645), coarse.replace(period=0.164)]
    told = ("2 of 3 instances (the first params[0], period 0.1635 s) have a period that is not "
            "a whole number of steps (dt = 0.001 s): their cycles begin between steps, and "
            "steady_speed_mm_s and steady_signed_speed_mm_s, taken at cycle starts, are NaN (a "
            "dt that divides the period, or adaptive steps, give them)")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run = ts.simulate(batch, 0.33)
    assert [str(warning.message) for warning in caught] == [told]
    steady = run.summary["steady_speed_mm_s"]
    assert steady.iloc[:2].isna().all() and np.isfinite(steady.iloc[2])
    assert (run.summary["status"] == "ok").all()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        chunked = run_batch(batch, 0.33, chunk_size=1)
    assert [str(warning.message) for warning in caught] == [told]
    pd.testing.assert_frame_equal(chunked.summary.drop(columns=["instance", "duration_s"]),
                                  run.summary, check_exact=True)


def test_an_adaptive_run_a_hair_short_of_whole_periods_is_told_it_leaves_the_last_out():
    """An adaptive run of 0.4 − 10⁻⁷ s of a 0.2-s robot ends before its second cycle does:
    the steady speeds (from cycle 1) leave it out, here NaN; they did silently (an audit,
    2026-12). One warning per call or batch; the whole two periods take it in."""
    import warnings

    from taichi_star.batch import run_batch

    robot = ts.StarParams(gait="A1+A3", n_arc=6, n_limb=2, period=0.2)
    solver = ts.SolverConfig(integrator="bdf2", adaptive=True, dt=0.005, dt_max=0.02)
    told = ("duration_s = 0.3999999 s ends 1e-07 s short of 2 whole periods of 2 of 2 instances "
            "(the first params[0], period 0.2 s): their steady speeds leave out the last of them "
            "(duration_s = 0.4 s takes it in)")
    for run in (lambda: ts.simulate([robot, robot], 0.4 - 1e-7, solver),
                lambda: run_batch([robot, robot], 0.4 - 1e-7, solver=solver, chunk_size=1)):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            short = run()
        assert [str(warning.message) for warning in caught] == [told]
        assert short.summary["steady_speed_mm_s"].isna().all()
    assert np.isfinite(ts.simulate([robot], 0.4, solver).summary["steady_speed_mm_s"]).all()


def test_a_record_of_adaptive_runs_of_different_ends_has_one_time():
    """Three cycles of a 0.2-s and a 0.25-s robot, recorded every 0.2 s with adaptive steps:
    the first run ends at 0.6 s, where its last record stopped, the second ran past 3 × 0.2 =
    0.6000000000000001 s; the record had two times, and the Dataset two half-empty columns
    (an audit, 2026-12). A record's time is its multiple of the interval."""
    from taichi_star.batch import run_batch

    robot = ts.StarParams(gait="A1+A3", n_arc=6, n_limb=2, period=0.2)
    solver = ts.SolverConfig(integrator="bdf2", adaptive=True, dt=0.005, dt_max=0.02)
    batch = run_batch([robot, robot.replace(period=0.25)], cycles=3, solver=solver,
                      record_interval_s=0.2)
    assert batch.summary["duration_s"].tolist() == [0.6, 0.75]
    times = [k * 0.2 for k in range(4)]
    for instance in (0, 1):
        assert batch.trajectory.query("instance == @instance")["t_s"].tolist() == times
    dataset = batch.to_xarray()
    assert dataset["time"].values.tolist() == times
    assert np.isfinite(dataset["centroid_x_mm"].values).all()


def test_a_float_column_without_a_unit_suffix_is_dimensionless_in_the_dataset(recorded):
    """Every variable carries `units`: "1" for a number whose name tells no unit (a float as
    well as a count), "" for text (a mutation audit: floats lost their "1" unnoticed)."""
    units = {name: variable.attrs["units"]
             for name, variable in recorded.to_xarray().variables.items()}
    assert units["max_strain"] == units["newton_iterations_mean"] == units["steps"] == "1"
    assert units["status"] == ""


def test_a_damaged_file_with_an_upper_case_parquet_suffix_is_named_as_parquet(recorded,
                                                                             tmp_path):
    """A damaged file is read by its suffix, whatever its case: a ValueError naming the file,
    not a missing CSV sidecar's FileNotFoundError."""
    from taichi_star.output import read_provenance

    path = recorded.to_parquet(tmp_path / "r.PARQUET")
    path.write_bytes(b"not a parquet file at all")
    with pytest.raises(ValueError, match=r"r\.PARQUET: no taichi_star provenance"):
        read_provenance(path)


def test_summary_of_dataset_refuses_what_is_not_a_result_dataset(recorded, tmp_path):
    """A path, None or a foreign Dataset raised AttributeError or KeyError (an audit)."""
    import xarray as xr

    path = recorded.to_netcdf(tmp_path / "r.nc")
    for wrong in (path, None, xr.Dataset({"a": ("x", [1.0])})):
        with pytest.raises(ValueError, match=r"^dataset must be an xarray Dataset of "):
            summary_of_dataset(wrong)


@pytest.mark.parametrize("name,frame", [("shapes.gif", "world"), ("shapes.mp4", "body")])
def test_animation_writes_a_movie_of_every_record(recorded, tmp_path, name, frame):
    path = recorded.animate(tmp_path / name, frame=frame, size_px=300)
    assert path.stat().st_size > 1000
    if name.endswith(".gif"):
        from PIL import Image

        with Image.open(path) as movie:
            assert movie.n_frames == 6


def test_animation_colours_the_heating_actuators_and_draws_the_path(recorded, tmp_path):
    """Records at 0, 0.04, ..., 0.2 s: the fired actuators are red during the heating pulse
    (t < t0 = 0.163 s and 0.15 s) and not after it; the centroid's path is drawn (blue)."""
    from PIL import Image

    path = recorded.animate(tmp_path / "heat.gif", instances=[0, 1], size_px=300)
    with Image.open(path) as movie:
        pictures = []
        for index in (0, movie.n_frames - 1):
            movie.seek(index)
            pictures.append(np.asarray(movie.convert("RGB")).astype(int))
    red = [int(((p[..., 0] > 200) & (p[..., 1] < 80) & (p[..., 2] < 80)).sum()) for p in pictures]
    assert red[0] > 100 and red[1] == 0
    blue = pictures[1][..., 2] - pictures[1][..., 0]
    assert (blue > 120).sum() > 0  # tab:blue path (lightsteelblue cylinder: difference < 80)


def test_an_animation_leaves_the_plotting_backend_and_pyplots_figures_alone(recorded, tmp_path):
    """animate switched matplotlib to Agg (`matplotlib.use`), also where it then refused the
    call: in a notebook every later figure stopped showing (an audit, 2026-12). It draws on
    a figure of its own, outside pyplot."""
    import matplotlib
    import matplotlib.pyplot as plt

    before = matplotlib.get_backend()
    matplotlib.use("svg")  # not Agg, as a notebook's inline backend is not
    try:
        figures = plt.get_fignums()
        recorded.animate(tmp_path / "movie.gif", instances=[0], size_px=100)
        with pytest.raises(ValueError, match="must end in .mp4 or .gif"):
            recorded.animate(tmp_path / "movie.avi")
        assert matplotlib.get_backend() == "svg"
        assert plt.get_fignums() == figures
    finally:
        matplotlib.use(before)


def test_a_movie_is_written_whole_or_leaves_the_previous_one(recorded, tmp_path, full_disk):
    """Drawing a movie over an earlier one fails at the disk (fsync reports it full): the earlier
    file is byte for byte as it was and nothing else is left in its folder."""
    path = recorded.animate(tmp_path / "movie.gif", instances=[0], size_px=200)
    written = path.read_bytes()

    with full_disk():
        with pytest.raises(OSError, match="No space left"):
            recorded.animate(path, instances=[1], size_px=200)
    assert path.read_bytes() == written
    assert [p.name for p in tmp_path.iterdir()] == ["movie.gif"]


@pytest.mark.parametrize("name, failing, error, reason", [
    ("r.nc", "xarray.Dataset.to_netcdf", RuntimeError("NetCDF: HDF error"), "NetCDF: HDF error"),
    # netCDF4's word for ENOSPC; the folder was just written into, so the disk is the suspect
    ("r.nc", "xarray.Dataset.to_netcdf", PermissionError(13, "Permission denied"),
     "netCDF4 reported: Permission denied; the folder is writable, so the disk may be full"),
    ("r.gif", "matplotlib.animation.Animation.save", OSError(28, "No space left on device"),
     "No space left on device"),
    ("r.mp4", "matplotlib.animation.Animation.save",
     subprocess.CalledProcessError(1, ["/opt/bin/ffmpeg", "-y"]), "ffmpeg exited with status 1")])
def test_a_file_drawn_beside_first_fails_naming_the_file_asked_for(recorded, tmp_path,
                                                                   monkeypatch, name, failing,
                                                                   error, reason):
    """On a real full disk the scratch copy fails first (an audit): netCDF's library raised
    "RuntimeError: NetCDF: HDF error" or a PermissionError ("Permission denied", which sent
    users after permissions), a GIF an OSError naming no file, ffmpeg a CalledProcessError.
    Each is now an OSError naming the file asked for, and the scratch folder beside it is
    gone."""
    def fail(*args, **kwargs):
        raise error
    monkeypatch.setattr(failing, fail)
    write = recorded.to_netcdf if name.endswith(".nc") else recorded.animate
    with pytest.raises(OSError, match=rf"^cannot write {re.escape(name)} \({reason}\)$"):
        write(tmp_path / name)
    assert list(tmp_path.iterdir()) == []


def test_animation_refuses_results_without_shapes(tmp_path):
    result = ts.simulate([ts.StarParams()], 0.01)
    with pytest.raises(ValueError, match="record_shapes"):
        result.animate(tmp_path / "x.gif")


def test_import_prints_nothing():
    out = subprocess.run([sys.executable, "-c", "import taichi_star"], capture_output=True,
                         text=True, check=True)
    assert out.stdout == "" and "[Taichi]" not in out.stderr


def test_import_prints_nothing_where_the_output_is_a_notebooks():
    """Where sys.stdout is not the process's (a notebook's kernel), Taichi's import logged
    "Graphical python shell detected, using wrapped sys.stdout" in every new kernel's first
    cell (an audit, 2026-12); the package asks Taichi not to take over such an output."""
    environment = {key: value for key, value in os.environ.items()
                   if key != "TI_ENABLE_PYBUF"}
    code = "import io, sys; sys.stdout = io.StringIO(); import taichi_star"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=environment)
    assert out.stderr == ""


def test_the_documented_result_columns_are_the_summary_columns_with_their_units(recorded):
    """SimulationResult's column table (name | unit | meaning, "—" for no unit) lists every
    summary column after the parameter columns, in order, with the unit `column_unit` gives."""
    rows = [line.strip().strip("|").split("|") for line in ts.SimulationResult.__doc__.splitlines()
            if line.strip().startswith("| ") and not line.strip().startswith("| column")]
    documented = [(name.strip(), unit.strip()) for name, unit, _ in rows]
    parameter_columns = list(ts.StarParams.columns().values())
    assert list(recorded.summary.columns[:len(parameter_columns)]) == parameter_columns
    results = list(recorded.summary.columns[len(parameter_columns):])
    assert [name for name, _ in documented] == results
    for name, unit in documented:
        assert unit == (column_unit(name) or "—"), name


@pytest.mark.parametrize("title", [None, "Gait A1+A3+A5 of the identified model, cycles 1 to 6"])
@pytest.mark.parametrize("size_px", [100, 150, 300, 720])
def test_an_animations_heading_fits_its_width_at_every_size(size_px, title):
    """At the smallest sizes the heading's fixed font ran over both sides of the movie (an
    audit, 2026-12). Now its font shrinks to fit, down to HEADING_LEAST_PT, and only there do
    its lines wrap; every word stays; a heading that fits keeps its font (720 px, the
    default, without a title)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from taichi_star.output import HEADING_LEAST_PT, HEADING_WIDTH_SHARE, _fit_heading

    figure = Figure(figsize=(size_px / 100, size_px / 100), dpi=100)
    FigureCanvasAgg(figure)  # as animate's figures are drawn
    label = figure.suptitle("")
    default_pt = label.get_fontsize()
    heading = (f"{title}\n" if title else "") + \
        "t = 12.00 s (world frame; red: actuators heating)"
    wrap, heading_bottom = _fit_heading(figure, label, heading)
    extent = label.get_window_extent(figure.canvas.get_renderer())
    assert extent.width <= HEADING_WIDTH_SHARE * figure.bbox.width
    assert 0 <= extent.x0 and extent.x1 <= figure.bbox.width and extent.y1 <= figure.bbox.height
    assert heading_bottom == pytest.approx(extent.y0 / figure.bbox.height, rel=1e-12)
    assert label.get_text().split() == heading.split()
    assert HEADING_LEAST_PT <= label.get_fontsize() <= default_pt
    if wrap is not None:
        assert label.get_fontsize() == HEADING_LEAST_PT
        assert max(map(len, label.get_text().splitlines())) <= wrap
    if size_px == 720 and title is None:
        assert (wrap, label.get_fontsize()) == (None, default_pt)
    if size_px == 100:  # 50 characters do not fit an inch at 4 pt
        assert wrap is not None


def test_a_failed_instance_is_held_at_its_last_shape_in_an_animation():
    """A failed instance's records are NaN from its failure on, and its panel went empty
    without a word (an audit, 2026-12): its frames hold the last finite shape (the panel's
    title says the status and time); a running instance's frames are untouched."""
    from taichi_star.output import _held_after_failure

    shapes = np.arange(3 * 2 * 4 * 2, dtype=float).reshape(3, 2, 4, 2)
    shapes[1:, 1] = np.nan  # instance 1 failed after the first record
    held = _held_after_failure(shapes)
    np.testing.assert_array_equal(held[:, 0], shapes[:, 0])
    np.testing.assert_array_equal(held[1], np.stack([shapes[1, 0], shapes[0, 1]]))
    np.testing.assert_array_equal(held[2, 1], shapes[0, 1])
    assert np.isnan(shapes[2, 1]).all()  # a copy: the result's shapes stay NaN


def _flip_first(data: bytes, value: float) -> bytes:
    """`data` with the last byte of the first little-endian float64 `value` in it inverted."""
    import struct

    at = data.index(struct.pack("<d", value)) + 7
    return data[:at] + bytes([data[at] ^ 0xFF]) + data[at + 1:]


def test_a_flipped_value_in_a_parquet_or_netcdf_file_is_an_error_not_another_number(
        recorded, tmp_path):
    """A byte flipped in a Parquet file's values read back as another number, with
    read_provenance vouching for the file, and in a netCDF file likewise (an audit, 2026-12:
    390 of 42,648 single-byte flips of a Parquet file, 38 of 3,096 sampled of a netCDF file).
    Parquet pages carry CRCs that read_provenance verifies; netCDF variables Fletcher-32
    checksums that HDF5 verifies for any reader."""
    xr = pytest.importorskip("xarray")
    alpha = RECORDED_PARAMS[1].alpha  # 0.5, in the summary's alpha column
    parquet = recorded.to_parquet(tmp_path / "r.parquet")
    ts.output.read_provenance(parquet)  # whole: no error
    # whole, the file gives the recorded values back bit for bit: the error below is the flip's
    np.testing.assert_array_equal(pd.read_parquet(parquet)["alpha"], recorded.summary["alpha"])
    damaged = tmp_path / "damaged.parquet"
    damaged.write_bytes(_flip_first(parquet.read_bytes(), alpha))
    with pytest.raises(ValueError, match=r"damaged.parquet: its values are damaged \(could not "
                                         r"verify page integrity, CRC checksum verification "
                                         r"failed"):
        ts.output.read_provenance(damaged)
    netcdf = recorded.to_netcdf(tmp_path / "r.nc")
    with xr.open_dataset(netcdf) as dataset:
        x_mm = dataset["centroid_x_mm"].values
    np.testing.assert_array_equal(
        x_mm, recorded.trajectory.pivot(index="instance", columns="t_s")["x_mm"].to_numpy())
    value = float(x_mm[np.isfinite(x_mm) & (x_mm != 0)][0])
    damaged = tmp_path / "damaged.nc"
    damaged.write_bytes(_flip_first(netcdf.read_bytes(), value))
    # netCDF4's words for HDF5's failed Fletcher-32 check (it names no checksum; HDF5 prints
    # nothing either): the file opens, its damaged variable does not read
    with pytest.raises(RuntimeError, match=r"^NetCDF: HDF error$"):
        with xr.open_dataset(damaged) as dataset:
            dataset["centroid_x_mm"].values


def test_a_table_sorted_in_place_keeps_each_instance_its_own_values():
    """A user's `result.summary.sort_values(..., inplace=True)` (or the sensitivities') kept
    the rows' labels, and `to_xarray` and `sensitivity` matched rows by position: every
    instance got another's values (an audit, 2026-12). Both read the tables in the run's order
    now, the dataset's positions are a copy (editing them changed the result's shapes), and
    a table whose labels no longer number its rows is refused, naming it (labels renumbered
    after a sort, `reset_index(inplace=True)`, cannot be told from the run's own)."""
    params = [ts.StarParams(gait="A1+A2", alpha=alpha) for alpha in (0.6, 0.8, 1.0)]
    result = ts.simulate(params, 0.1, ts.SolverConfig(dt=5e-3), record_interval_s=0.05,
                         record_shapes=True, sensitivities=("alpha",))
    before = result.to_xarray()
    derivative = result.sensitivity("speed_mm_s", "alpha")
    result.summary.sort_values("alpha", ascending=False, inplace=True)
    result.sensitivities.sort_values(result.sensitivities.columns[0], inplace=True)
    after = result.to_xarray()
    for name in ("alpha", "speed_mm_s", "centroid_x_mm", "d_speed_mm_s__d_alpha"):
        np.testing.assert_array_equal(after[name].values, before[name].values, err_msg=name)
    np.testing.assert_array_equal(result.sensitivity("speed_mm_s", "alpha"), derivative)
    after["positions"][0, 0, 0, 0] = -5.0
    assert result.shapes[0, 0, 0, 0] != -5.0
    result.summary.index = [5, 6, 7]  # labels that no longer number the rows: refused
    with pytest.raises(ValueError, match=r"^result.summary: its rows are no longer labelled "
                                         r"0..2 in the run's order"):
        result.to_xarray()


def test_the_files_record_when_the_result_was_made_and_when_written(recorded, tmp_path):
    """The files' `date` was the moment each was written, so a result saved later claimed a
    later run (an audit, 2026-12): `date` is the result's own (`made_at`, set when it is built),
    `written` the file's."""
    assert recorded.made_at is not None
    made = dataclasses.replace(recorded, made_at="2020-01-02T03:04:05+00:00")
    path = made.to_parquet(tmp_path / "made.parquet")
    facts = ts.output.read_provenance(path)
    assert facts["date"] == "2020-01-02T03:04:05+00:00"
    assert facts["written"] != facts["date"] and facts["written"].startswith("20")
