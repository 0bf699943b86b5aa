"""The scaling study's table: its ratios are its rounds' wall times' and every row names the
machine, the code and the model timed. The executors are stood in by in-process ones (worker
processes cost seconds each to start, and the executors are tested in
tests/studies/test_batch.py)."""

import contextlib

import numpy as np
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
    # a short hash of digits alone (one in 27 is; CI's once was), a leading zero too: read back
    # as text, not the number 813637
    monkeypatch.setattr(provenance, "short_commit", lambda: "0813637")
    scaling.main(["--quick", "--no-dask", "--workers-list", "1", "--rounds", "3",
                  "--no-progress", "--out", str(tmp_path)])
    table = pd.read_csv(tmp_path / "scaling.csv", dtype={"commit": str})
    assert table["mode"].tolist() == ["in-process", "stand-in"]
    # three interleaved rounds: the best, the median and the ratio (the median of each round's
    # pair) are of the rounds' own wall times (6 significant digits in wall_s_rounds)
    rounds = np.array([[float(t) for t in text.split(";")] for text in table["wall_s_rounds"]])
    assert rounds.shape == (2, 3) and (table["rounds"] == 3).all()
    np.testing.assert_allclose(table["wall_s"], rounds.min(axis=1), rtol=1e-5)
    np.testing.assert_allclose(table["wall_s_median"], np.median(rounds, axis=1), rtol=1e-5)
    np.testing.assert_allclose(table["speedup_vs_in_process"],
                               np.median(rounds[0] / rounds, axis=1), rtol=2e-5)
    assert table["same_table_as_in_process"].all()
    assert (table["robot_steps"] == table["instances"] * table["steps_per_instance"]).all()
    assert (table["precision"] == "f64").all() and (table["preset"] == "paper").all()
    for column, value in provenance.timing_columns("cpu").items():
        # an empty cell (no GPU) reads back as a float NaN: compared as text "" (a float
        # column filled with text warns in pandas 3 and is refused by later versions)
        assert (table[column].astype(object).fillna("") == value).all(), column
