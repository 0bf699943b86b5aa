"""The discretisation convergence study: Richardson limit and order on synthetic power laws, and
the study in --quick mode against a direct simulation."""

import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams

from studies import cli, convergence


def _synthetic(limit, constant, order, n_arcs, ends):
    return [{"gait": "A1+A2", "actuation_ends": ends, "n_arc": n, "n_limb": 6,
             "speed_mm_s": limit - constant / n ** order,
             "signed_speed_mm_s": limit - constant / n ** order, "status": "ok"} for n in n_arcs]


@pytest.mark.parametrize("order", [1.0, 2.0])
def test_richardson_limit_and_order_are_exact_for_a_power_law(order):
    """S(n) = L − C/n^p: three doublings give p and L exactly (to round-off)."""
    summary = pd.DataFrame(_synthetic(1.87, 5.0, order, [18, 36, 72], "shared")
                           + _synthetic(1.87, 9.0, 1.0, [18, 36, 72], "clamped"))
    table = convergence.convergence_table(summary)
    shared = table[table.actuation_ends == "shared"]
    # the speeds are ~1.87 mm/s to their rounding (2.2e-16), and the last difference Richardson
    # divides by is 2.9e-3 mm/s (p = 2): the order is exact to ~3e-13 (8e-14 measured), the
    # limit to a few of its ulps (1 measured), the relative errors, (S − L)/L over S − L >=
    # 0.015 mm/s, to ~1e-14 (4e-15 measured); p = 1 is exact but for an ulp
    assert shared.observed_order.iloc[0] == pytest.approx(order, rel=1e-12)
    assert shared.limit_mm_s.iloc[0] == pytest.approx(1.87, rel=1e-14)
    expected = 5.0 / 18 ** order / 1.87
    assert shared.sort_values("n_arc").relative_error.iloc[0] == pytest.approx(expected, rel=1e-12)
    clamped = table[table.actuation_ends == "clamped"].sort_values("n_arc")
    assert clamped.relative_error.iloc[-1] == pytest.approx(9.0 / 72 / 1.87, rel=1e-12)
    assert table.n_nodes.tolist()[:3] == [193, 337, 625]


def test_a_robot_that_reverses_between_meshes_is_not_read_as_converging():
    """The magnitudes of signed speeds −0.02, 0.06, 0.10 mm/s (a robot that swims the other
    way on the coarsest mesh) gave an order of −5e-16, a limit of −1.2e14 mm/s and every error
    1.0 (an audit, 2026-12); the signed speeds give order 1 and limit 0.14 mm/s, and the
    coarsest mesh's error is then its signed distance from it, 114 %."""
    rows = [{"gait": "A1", "actuation_ends": "clamped", "n_arc": n, "n_limb": 6,
             "speed_mm_s": abs(v), "signed_speed_mm_s": v, "status": "ok"}
            for n, v in ((18, -0.02), (36, 0.06), (72, 0.10))]
    table = convergence.convergence_table(pd.DataFrame(rows)).sort_values("n_arc")
    assert table.observed_order.iloc[0] == pytest.approx(1.0, rel=1e-12)
    assert table.limit_mm_s.iloc[0] == pytest.approx(0.14, rel=1e-12)
    assert table.relative_error.iloc[0] == pytest.approx(0.16 / 0.14, rel=1e-12)
    # growing changes (a diverging ladder): no order to trust, no limit, no errors
    rows = [dict(row, signed_speed_mm_s=v, speed_mm_s=v)
            for row, v in zip(rows, (0.10, 0.11, 0.15))]
    diverging = convergence.convergence_table(pd.DataFrame(rows))
    assert (diverging.observed_order < 0).all() and diverging.limit_mm_s.isna().all()
    assert diverging.relative_error.isna().all()


@pytest.mark.slow
def test_quick_run_writes_table_and_plot(tmp_path):
    table = convergence.main(["--quick", "--out", str(tmp_path), "--no-progress"])
    assert {"observed_order", "limit_mm_s", "relative_error", "n_nodes"} <= set(table.columns)
    assert len(table) == 6 and (table.status == "ok").all()
    written = pd.read_csv(tmp_path / "convergence.csv")
    direct = taichi_star.simulate([StarParams(gait="A1+A2", n_arc=8, actuation_ends="shared")],
                                  cli.QUICK_DURATION_S, SolverConfig(dt=cli.QUICK_DT)).summary
    row = written[(written.n_arc == 8) & (written.actuation_ends == "shared")]
    # the CSV keeps 10 significant digits of the same bits (a result does not depend on its
    # batch): exactly the direct speed's
    assert row.speed_mm_s.iloc[0] == float(f"{direct.speed_mm_s.iloc[0]:.10g}")
    assert (tmp_path / "convergence.png").stat().st_size > 1000


@pytest.mark.parametrize("text", ["18,36", "18,30,60", "1,2,4"])
def test_n_arc_list_must_double(text):
    with pytest.raises(cli.StudyArgumentError, match="--n-arc"):
        convergence.parse_n_arc(text)
