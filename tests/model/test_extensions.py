"""The model extensions (docs/model.md): linear drag on the rods and the hub and
per-actuator gains and delays, in the engine: off by default and compiled out, per instance,
and carried through result tables (their validation is in tests/unit/test_params.py). Elsewhere: the reference's elements against
finite differences and its actuation against the profile's formula (tests/model/
test_reference.py), the engine against the reference with them on (tests/model/test_engine.py,
`test_engine_matches_reference_with_damping_joints_ends_closure_and_extensions`) and the linear
drag term assembled alone (tests/unit/test_assembly.py).
"""

import numpy as np
import pandas as pd
import pytest

import taichi_star as ts
from taichi_star.model import build_model

# ---- the engine -------------------------------------------------------------------------------

def test_extensions_are_off_by_default_and_compiled_out():
    model = build_model([ts.StarParams.preset("paper"), ts.StarParams.preset("accurate")
                         .replace(n_arc=18)])
    assert "linear_drag" not in [cls.name for cls, _ in model.terms_used]
    for preset in ("paper", "accurate"):
        params = ts.StarParams.preset(preset)
        assert (params.linear_drag, params.hub_linear_drag) == (0.0, 0.0)
        assert params.actuator_gains == (1.0,) * 8 and params.actuator_delays == (0.0,) * 8


def test_per_actuator_values_are_per_instance():
    """Instances differing only in A2's gain (or in A2's delay) run in one batch exactly as each
    alone (one thread per instance); a gain or delay of an actuator the gait does not fire
    changes nothing, to the bit; A2's gain does change an A1+A2 gait."""
    base = ts.StarParams(gait="A1+A2")
    batch = [base, base.replace(actuator_gains=(1, 0.7, 1, 1, 1, 1, 1, 1)),
             base.replace(actuator_delays=(0, 0.02, 0, 0, 0, 0, 0, 0)),
             base.replace(actuator_gains=(1, 1, 1, 1, 1, 3.0, 1, 1),
                          actuator_delays=(0, 0, 0, 0, 0, 0, 0.5, 0))]
    together = ts.simulate(batch, 0.05, record_interval_s=0.05).summary
    for index, params in enumerate(batch[:3]):
        alone = ts.simulate([params], 0.05, record_interval_s=0.05).summary
        pd.testing.assert_frame_equal(alone.reset_index(drop=True),
                                      together.iloc[[index]].reset_index(drop=True),
                                      check_exact=True)
    columns = ["displacement_x_mm", "displacement_y_mm", "heading_deg"]
    np.testing.assert_array_equal(together.loc[3, columns], together.loc[0, columns])
    # A1+A2 swims along the bisector of A1 (0°) and A2 (45°) by its mirror symmetry; early in
    # the pulse each arm's stroke adds its push, so a weaker (gain 0.7) or later (by 20 ms)
    # A2 pushes less: the robot moves less and turns towards A1 (measured 1.035 mm/s at
    # 22.5°; 0.872 at 22.09° and 0.689 at 14.44°)
    assert together.travel_direction_deg[0] == pytest.approx(22.5, abs=1e-9)
    for weaker in (1, 2):
        assert together.speed_mm_s[weaker] < together.speed_mm_s[0]
        assert 0.0 < together.travel_direction_deg[weaker] < 22.5


# ---- parameters (their validation: tests/unit/test_params.py) -----------------------------------

def test_extension_fields_survive_csv_and_parquet_round_trips(tmp_path):
    """The summary holds the per-actuator tuples as their text (like the actuator profile, a
    type every table format has); to_csv or to_parquet, read back, and from_row gives the same
    StarParams, to the bit (a float's repr reads back exactly)."""
    params = ts.StarParams(gait="A1+A2", linear_drag=12.5, hub_linear_drag=0.1 + 0.2,
                           actuator_gains=(1.0, 0.1 + 0.2, 1, 1, 1, 1, 1, 2.5),
                           actuator_delays=(0.0, 1 / 3, 0, 0, 0, 0, 0, 0))
    result = ts.simulate([params], 0.002, record_interval_s=0.002)
    summary = result.summary
    assert summary["actuator_gains"][0] == str(params.actuator_gains)
    assert summary["linear_drag_pa_s_m"][0] == 12.5
    assert ts.StarParams.from_row(summary.iloc[0]) == params
    row = pd.read_csv(result.to_csv(tmp_path / "summary.csv")).iloc[0]
    assert ts.StarParams.from_row(row) == params
    row = pd.read_parquet(result.to_parquet(tmp_path / "summary.parquet")).iloc[0]
    assert ts.StarParams.from_row(row) == params
    assert ts.StarParams(actuator_delays="[0, 0.25, 0, 0, 0, 0, 0, 0]").actuator_delays[1] == 0.25
    with pytest.raises(ValueError, match="actuator_gains: cannot read 'a, b'"):
        ts.StarParams(actuator_gains="a, b")
