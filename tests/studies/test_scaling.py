"""The scaling study's table: its ratios are its wall times' and every row names the machine,
the code and the model timed. The executors are stood in by in-process ones (worker processes
cost seconds each to start, and the executors are tested in tests/studies/test_batch.py)."""

import contextlib

import pandas as pd

from taichi_star.batch import InProcess

from studies import provenance, scaling


def test_the_speedups_are_the_wall_times_ratios_and_rows_name_machine_and_code(monkeypatch,
                                                                             tmp_path):
    def in_process_modes(counts, dask):
        for workers in (0, *counts):
            yield ("in-process" if not workers else "stand-in", workers,
                   lambda: contextlib.nullcontext(InProcess()))

    monkeypatch.setattr(scaling, "modes", in_process_modes)
    scaling.main(["--quick", "--no-dask", "--workers-list", "1", "--no-progress", "--out",
                  str(tmp_path)])
    table = pd.read_csv(tmp_path / "scaling.csv")
    assert table["mode"].tolist() == ["in-process", "stand-in"]
    # the ratio is of the CSV's own wall times (10 significant digits each)
    ratio = table["wall_s"].iloc[0] / table["wall_s"]
    pd.testing.assert_series_equal(table["speedup_vs_in_process"], ratio, check_names=False,
                                   rtol=1e-9)
    assert table["same_table_as_in_process"].all()
    assert (table["robot_steps"] == table["instances"] * table["steps_per_instance"]).all()
    assert (table["precision"] == "f64").all() and (table["preset"] == "paper").all()
    for column, value in provenance.timing_columns("cpu").items():
        assert (table[column].fillna("") == value).all(), column
