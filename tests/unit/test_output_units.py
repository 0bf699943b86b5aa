"""Units of result columns from their names: parameters by table, metrics by suffix, the longest
suffix first (a rate per second is not a time)."""

import pytest

from taichi_star.output import column_unit, column_units
from taichi_star.params import PARAMETER_UNITS, PER_ACTUATOR_FIELDS, StarParams


@pytest.mark.parametrize("name, unit", [
    ("speed_mm_s", "mm/s"), ("displacement_x_mm", "mm"), ("heading_deg", "degree"),
    ("failure_time_s", "s"), ("robot_steps_per_s", "1/s"),
    ("timing_robot_seconds_per_wall_s", "1"), ("robot_seconds_per_s", "1"), ("bandwidth_gb_s", "GB/s"), ("h_ms", "ms"),
    ("step_us", "us"), ("impulse_x_n_s_m", "N*s/m"), ("impulse_along_n_s_m", "N*s/m"),
    ("jetting_s", "s"), ("youngs_modulus_pa", "Pa"), ("fluid_density_kg_m3", "kg/m^3"),
    ("cylinder_mass_per_height_kg_m", "kg/m"), ("joint_radius_m", "m"), ("status", ""),
    ("gait", ""),
    # sensitivities: the output's unit over the field's, the output's alone for a
    # dimensionless field, none where either has none
    ("d(x_mm)/d(alpha)", "mm"), ("d(x_mm)/d(youngs_modulus)", "mm/Pa"),
    ("d(speed_mm_s)/d(joint_radius)", "(mm/s)/m"),
    ("d(displacement_x_mm)/d(fluid_density)", "mm/(kg/m^3)"),
    ("d(x_mm)/d(actuator_delays[2])", "mm/s"), ("d(heading_deg)/d(actuator_gains[3])", "degree"),
    ("d(status)/d(alpha)", ""), ("d(x_mm)/d(gait)", ""),
    # a rate of turn is degrees per second, not seconds (an audit, 2026-12); a unit of two
    # factors in brackets: "mm/Pa*s" reads as mm·s/Pa
    ("angular_velocity_deg_s", "degree/s"), ("heading_deg", "degree"),
    ("d(x_mm)/d(hub_linear_drag)", "mm/(Pa*s)"),
    ("d(speed_mm_s)/d(wake_coupling)", "(mm/s)/(Pa*s)"),
    ("d(impulse_x_n_s_m)/d(alpha)", "N*s/m"), ("d(impulse_x_n_s_m)/d(joint_radius)", "(N*s/m)/m")])
def test_column_unit_by_parameter_or_suffix(name, unit):
    assert column_unit(name) == unit


def test_the_longest_matching_suffix_counts_whatever_the_tables_order(monkeypatch):
    """impulse_x_n_s_m matched "_m" first and was in metres (an audit): the longest suffix
    counts, so a table listing the short suffixes first gives the same units."""
    from taichi_star import output

    reordered = dict(sorted(output.UNITS.items(), key=lambda item: len(item[0])))
    monkeypatch.setattr(output, "UNITS", reordered)
    assert column_unit("impulse_x_n_s_m") == "N*s/m" and column_unit("robot_steps_per_s") == "1/s"
    assert column_unit("thickness_m") == "m" and column_unit("jetting_s") == "s"


def test_every_numeric_parameter_has_a_unit_and_unitless_columns_are_left_out():
    numeric = {name for name in StarParams.field_names()
               if isinstance(getattr(StarParams(), name), (int, float))} | set(PER_ACTUATOR_FIELDS)
    assert numeric == set(PARAMETER_UNITS)
    assert column_units(["alpha", "status", "speed_mm_s"]) == {"alpha": "1", "speed_mm_s": "mm/s"}


def test_every_column_with_a_unit_names_it_and_every_parameter_column_maps_back():
    """A parameter column is its field name plus the unit's suffix (none for "1"); the suffix
    gives the unit back, and the names are unique."""
    columns = StarParams.columns()
    assert len(set(columns.values())) == len(columns)
    for name, column in columns.items():
        unit = PARAMETER_UNITS.get(name, "1")
        assert column.startswith(name)
        assert (column == name) == (unit == "1"), (name, column)
        if unit != "1":
            assert column_unit(column) == unit


def test_every_committed_sidecar_gives_its_columns_the_units_their_names_do():
    """A sidecar's units are read off the column names when the table is written: a wrong
    suffix rule (impulse_x_n_s_m read as "m", an audit, 2026-12) stays in every committed
    sidecar written under it. Each unit in results/ equals today's rule's (columns the rule
    does not know, None, are left out)."""
    import json
    from pathlib import Path

    checked = 0
    for path in (Path(__file__).resolve().parents[2] / "results").rglob("*.json"):
        units = json.loads(path.read_text()).get("units") if path.suffixes[-2:-1] else None
        for column, unit in (units or {}).items():
            expected = column_unit(column)
            if expected is not None:
                assert unit == expected, (path.name, column, unit, expected)
                checked += 1
    assert checked > 1000   # the committed sidecars' units were all read
