"""What a notebook cell shows of a SimulationResult (`_repr_html_`): the repr's line, the
sensitivities' parameters, the first rows of the main summary columns and how many are left."""

import html
import re

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.simulation import NOTEBOOK_COLUMNS, NOTEBOOK_ROWS


def result_of(rows, sensitivities=(), instance_column=False):
    summary = pd.DataFrame({"gait": ["A1+A3"] * rows,
                            "signed_speed_mm_s": np.arange(rows) + 0.5,
                            "status": ["ok"] * (rows - 1) + ["newton_failed"],
                            "youngs_modulus_pa": 5e6})
    if instance_column:
        summary.insert(0, "instance", np.arange(rows) + 100)
    trajectory = pd.DataFrame({"instance": pd.Series(dtype=np.int64),
                               "t_s": pd.Series(dtype=np.float64)})
    return ts.SimulationResult(summary=summary, trajectory=trajectory, shapes=None,
                               topology=None, solver=ts.SolverConfig(),
                               arguments={"sensitivities": list(sensitivities)})


def body_rows(view):
    return re.findall(r"<tr>\s*<th>(\d+)</th>", view)


@pytest.mark.parametrize("rows, more", [(NOTEBOOK_ROWS, None), (NOTEBOOK_ROWS + 1, 1)])
def test_the_first_rows_are_shown_and_the_rest_counted(rows, more):
    view = result_of(rows)._repr_html_()
    assert body_rows(view) == [str(i) for i in range(NOTEBOOK_ROWS)]
    assert ("more rows" in view) is (more is not None)
    if more is not None:
        assert f"{more} more rows; all 4 columns" in view
    else:
        assert "<p>all 4 columns: <code>result.summary</code></p>" in view


def test_the_repr_line_is_escaped_and_only_the_main_columns_shown():
    result = result_of(3)
    view = result._repr_html_()
    assert f"<code>{html.escape(repr(result))}</code>" in view
    assert "'ok'" not in view  # the status counts' quotes escaped
    header = re.findall(r"<th>([a-z_]+)</th>", view)
    assert header == ["gait", "signed_speed_mm_s", "status"]
    assert set(header) <= set(NOTEBOOK_COLUMNS) and "youngs_modulus_pa" not in view
    assert "<td>newton_failed</td>" in view and "<td>2.5</td>" in view


def test_a_batchs_instance_numbers_and_the_sensitivities_are_shown():
    view = result_of(2, sensitivities=("alpha", "actuator_gains[2]"),
                     instance_column=True)._repr_html_()
    assert re.findall(r"<th>([a-z_]+)</th>", view)[0] == "instance"
    assert "<td>101</td>" in view
    assert "differentiated by alpha, actuator_gains[2]" in view
    assert "differentiated" not in result_of(2)._repr_html_()
