"""Units of result columns from their names: parameters by table, metrics by suffix, the longest
suffix first (a rate per second is not a time)."""

import pytest

from taichi_star.output import PARAMETER_UNITS, column_unit, column_units
from taichi_star.params import StarParams


@pytest.mark.parametrize("name, unit", [
    ("speed_mm_s", "mm/s"), ("displacement_x_mm", "mm"), ("heading_deg", "degree"),
    ("failure_time_s", "s"), ("robot_steps_per_s", "1/s"),
    ("timing_robot_seconds_per_wall_s", "1/s"), ("bandwidth_gb_s", "GB/s"), ("h_ms", "ms"),
    ("step_us", "us"), ("youngs_modulus", "Pa"), ("status", ""), ("gait", "")])
def test_column_unit_by_parameter_or_suffix(name, unit):
    assert column_unit(name) == unit


def test_every_numeric_parameter_has_a_unit_and_unitless_columns_are_left_out():
    numeric = {name for name in StarParams.field_names()
               if isinstance(getattr(StarParams(), name), (int, float))}
    assert numeric == set(PARAMETER_UNITS)
    assert column_units(["alpha", "status", "speed_mm_s"]) == {"alpha": "1", "speed_mm_s": "mm/s"}
