"""The discretisation convergence study (studies/convergence.py)."""

import pandas as pd
import pytest

from studies import common, convergence


def _synthetic(limit, constant, order, n_arcs, ends):
    return [{"gait": "A1+A2", "actuation_ends": ends, "n_arc": n, "n_limb": 6,
             "speed_mm_s": limit - constant / n ** order,
             "signed_speed_mm_s": limit - constant / n ** order, "status": "ok"} for n in n_arcs]


@pytest.mark.parametrize("order", [1.0, 2.0])
def test_richardson_limit_and_order_are_exact_for_a_power_law(order):
    """S(n) = L − C/n^p: three doublings give p and L exactly (to round-off)."""
    summary = pd.DataFrame(_synthetic(1.87, 5.0, order, [18, 36, 72], "shared")
                           + _synthetic(1.87, 9.0, 1.0, [18, 36, 72], "clamped")
                           + _synthetic(1.87, 9.0, 1.0, [320], "clamped"))
    table = convergence.convergence_table(summary)
    shared = table[table.actuation_ends == "shared"]
    assert shared.observed_order.iloc[0] == pytest.approx(order, rel=1e-9)
    assert shared.limit_mm_s.iloc[0] == pytest.approx(1.87, rel=1e-12)
    expected = 5.0 / 18 ** order / 1.87
    assert shared.sort_values("n_arc").relative_error.iloc[0] == pytest.approx(expected, rel=1e-9)
    preset = table[table.converged_preset]
    assert len(preset) == 1 and preset.relative_error.iloc[0] == pytest.approx(9.0 / 320 / 1.87)


def test_quick_run_writes_table_and_plot(tmp_path):
    table = convergence.main(["--quick", "--out", str(tmp_path), "--no-progress"])
    assert {"observed_order", "limit_mm_s", "relative_error", "n_nodes"} <= set(table.columns)
    assert len(table) == 6 and (table.status == "ok").all()
    assert (tmp_path / "convergence.png").stat().st_size > 0
    assert len(pd.read_csv(tmp_path / "convergence.csv")) == 6


@pytest.mark.parametrize("text", ["18,36", "18,30,60", "1,2,4"])
def test_n_arc_list_must_double(tmp_path, text):
    with pytest.raises(common.StudyArgumentError, match="--n-arc"):
        convergence.main(["--quick", "--out", str(tmp_path), "--n-arc", text])
