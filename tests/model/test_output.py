"""Labelled data (xarray / netCDF), animation and the quiet import."""

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.output import column_unit


RECORDED_PARAMS = [ts.StarParams(gait="A1+A2"), ts.StarParams(gait="A3", alpha=0.5)]


@pytest.fixture(scope="module")
def recorded():
    return ts.simulate(RECORDED_PARAMS, 0.2, ts.SolverConfig(dt=2e-3), record_interval_s=0.04,
                       record_shapes=True)


def test_a_summary_row_gives_its_parameters_back_also_from_a_csv(recorded, tmp_path):
    """StarParams.from_row reads the unit-suffixed columns of a summary row (in memory, and
    read back from a CSV, where the default actuator profile is text); a changed profile in
    a CSV must be given explicitly, and a missing column is named."""
    for index, params in enumerate(RECORDED_PARAMS):
        assert ts.StarParams.from_row(recorded.summary.iloc[index]) == params
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


def test_xarray_holds_the_tables_with_units_and_survives_netcdf(recorded, tmp_path):
    import xarray as xr

    dataset = recorded.to_xarray()
    assert dataset.sizes == {"instance": 2, "time": 6, "node": 193, "xy": 2}
    np.testing.assert_array_equal(dataset.speed_mm_s, recorded.summary.speed_mm_s)
    np.testing.assert_array_equal(dataset.alpha, [0.8, 0.5])
    assert dataset.speed_mm_s.attrs["units"] == "mm/s"
    assert dataset.youngs_modulus_pa.attrs["units"] == "Pa"
    last = recorded.trajectory[recorded.trajectory.t_s == recorded.trajectory.t_s.max()]
    np.testing.assert_array_equal(dataset.centroid_x_mm.isel(time=-1), last.x_mm)
    np.testing.assert_array_equal(dataset.positions, recorded.shapes)
    path = recorded.to_netcdf(tmp_path / "result.nc")
    with xr.open_dataset(path) as back:
        np.testing.assert_array_equal(back.positions, recorded.shapes)
        assert list(back.gait.values) == ["A1+A2", "A3"]


@pytest.mark.parametrize("name,frame", [("shapes.gif", "world"), ("shapes.mp4", "body")])
def test_animation_writes_a_movie_of_every_record(recorded, tmp_path, name, frame):
    path = recorded.animate(tmp_path / name, frame=frame, size_px=300)
    assert path.stat().st_size > 1000
    if name.endswith(".gif"):
        from PIL import Image

        with Image.open(path) as movie:
            assert movie.n_frames == 6


def test_animation_refuses_results_without_shapes(tmp_path):
    result = ts.simulate([ts.StarParams()], 0.01)
    with pytest.raises(ValueError, match="record_shapes"):
        result.animate(tmp_path / "x.gif")


def test_import_prints_nothing():
    out = subprocess.run([sys.executable, "-c", "import taichi_star"], capture_output=True,
                         text=True, check=True)
    assert out.stdout == "" and "[Taichi]" not in out.stderr


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
