"""Validation of the public parameters and of `simulate`'s arguments: every bad input is a
ValueError naming the field, raised before any compute."""

import dataclasses
import math
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.params import PARAMETER_UNITS
from taichi_star.gait import Gait, symmetry_classes
from taichi_star.geometry import build_topology
from taichi_star.params import (PER_ACTUATOR_FIELDS, PER_ACTUATOR_RANGES, SOLVER_RANGES,
                                allowed_values)


@pytest.mark.parametrize("field,value", [
    ("youngs_modulus", -5e6), ("youngs_modulus", 0.0), ("youngs_modulus", math.nan),
    ("limb_stiffness_ratio", 0.0), ("period", math.inf), ("period", 0.1), ("thickness", -1e-3),
    ("actuator_density", 0.0), ("foam_density", -1.0), ("fluid_density", math.nan),
    ("cylinder_mass_per_height", 0.0), ("cylinder_diameter", -0.03), ("joint_radius", 0.0),
    ("joint_radius", 0.03), ("tip_radius", 0.02), ("alpha", -0.1), ("alpha", math.nan),
    ("added_mass_coeff", -1.0), ("drag_parallel", -0.01), ("drag_perpendicular", math.inf),
    ("cylinder_drag", -10.0), ("cylinder_added_mass_coeff", -1.0), ("n_arc", 1),
    ("n_arc", 18.0), ("n_limb", 0), ("jet_mode", "sometimes"), ("youngs_modulus", "5e6"),
    ("actuation_ends", "free"), ("jet_inflow", -0.1), ("jet_inflow", 10.5),
    ("jet_inflow", math.nan), ("jet_direction", "radial"), ("jet_application", "tips"),
    ("hub_height", -0.05), ("foam_height", 0.6), ("actuator_height", math.inf),
])
def test_star_params_rejects_bad_values_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        ts.StarParams(**{field: value})


@pytest.mark.parametrize("gait", ["A9", "A1+A1", "", "A1+", "B2", "A1 A2", "A0", 3])
def test_unknown_gaits_are_rejected(gait):
    with pytest.raises(ValueError, match="gait"):
        ts.StarParams(gait=gait)


@pytest.mark.parametrize("field,value", [
    ("dt", 0.0), ("dt", -1e-3), ("dt", math.nan), ("dt", 2.0), ("dt", 0.2), ("newton_tol", 0.0),
    ("newton_tol", math.inf), ("newton_tol", 1.0), ("max_newton", 0), ("max_newton", 2.5),
    ("max_newton", 10_000), ("precision", "f16"), ("max_substep_halvings", 27),
    ("error_tol", 0.0), ("error_tol", -1e-7), ("dt_min", 0.0), ("dt_max", 1.0),
    ("adaptive", "yes"),
])
def test_solver_config_rejects_bad_values(field, value):
    with pytest.raises(ValueError, match=field):
        ts.SolverConfig(**{field: value})


def test_f32_needs_a_tolerance_it_can_resolve():
    """newton_tol at least 1e-7 m in f32: the default 1e-10 and a hair under 1e-7 refused,
    1e-7 itself accepted."""
    for tolerance in (1e-10, 1e-7 * (1 - 1e-12)):
        with pytest.raises(ValueError, match=r"^newton_tol must be in \[1e-07, 1e-06\] m with "
                                             r"precision 'f32'"):
            ts.SolverConfig(precision="f32", newton_tol=tolerance)
    assert ts.SolverConfig(precision="f32", newton_tol=1e-7).precision == "f32"


def test_newton_tol_defaults_to_the_precisions_own():
    """Left out, newton_tol is 1e-10 m in f64 (the presets' value since the start: their bits
    are unchanged) and 1e-7 m in f32 (the smallest it accepts), stored as a number; given,
    it is kept, also where it equals the other precision's default."""
    assert ts.SolverConfig().newton_tol == 1e-10
    assert ts.SolverConfig.preset("accurate").newton_tol == 1e-10
    assert ts.SolverConfig(precision="f32").newton_tol == 1e-7
    assert ts.SolverConfig.preset("accurate", precision="f32").newton_tol == 1e-7
    assert ts.SolverConfig(precision="f32") == ts.SolverConfig(precision="f32", newton_tol=1e-7)
    assert ts.SolverConfig(newton_tol=1e-7).newton_tol == 1e-7
    assert ts.NEWTON_TOL_DEFAULTS == {"f64": 1e-10, "f32": 1e-7}
    # the field table (help, the API page) says what the None stands for
    assert "| newton_tol | m | [1e-14, 1e-06] | None: 1e-10 in f64, 1e-07 in f32 |" \
        in ts.SolverConfig.__doc__
    # a run store records the changes from SolverConfig(): f32's tolerance is among them
    assert ts.changed_fields(ts.SolverConfig(precision="f32")) == {"newton_tol": 1e-7,
                                                                  "precision": "f32"}


def test_a_change_of_precision_takes_the_new_default_tolerance_only_from_the_old_default():
    """replace(precision=...) without newton_tol: the old precision's default becomes the new
    one's, both ways; any other tolerance is kept, and refused where f32 cannot use it."""
    assert ts.SolverConfig().replace(precision="f32").newton_tol == 1e-7
    assert ts.SolverConfig(precision="f32").replace(precision="f64").newton_tol == 1e-10
    assert ts.SolverConfig(precision="f32", newton_tol=5e-7).replace(
        precision="f64").newton_tol == 5e-7
    assert ts.SolverConfig().replace(precision="f32", newton_tol=3e-7).newton_tol == 3e-7
    # a hair off the default is another tolerance: kept, so f32 refuses it
    with pytest.raises(ValueError, match=r"^newton_tol must be in \[1e-07, 1e-06\] m with "):
        ts.SolverConfig(newton_tol=1e-10 * (1 + 1e-12)).replace(precision="f32")
    assert ts.SolverConfig().replace(dt=2e-3).newton_tol == 1e-10


def test_the_residual_test_is_opt_in():
    """None (the default) compares against infinity; a value is validated and used as is."""
    assert ts.SolverConfig().residual_tol is None
    assert ts.SolverConfig().residual_limit == math.inf
    assert ts.SolverConfig(residual_tol=np.float64(0.5)).residual_limit == 0.5
    # stored as a Python float (the definition hash and the manifests see the stored value)
    assert type(ts.SolverConfig(residual_tol=np.float32(0.5)).residual_tol) is float


@pytest.mark.parametrize("kwargs,match", [
    (dict(params=[]), "empty"),
    (dict(params=[ts.StarParams(), ts.StarParams(n_arc=36)]), "n_arc"),
    (dict(params=[ts.StarParams(), "A1"]), r"params\[1\]"),
    (dict(duration_s=0.0), "duration_s"),
    (dict(duration_s=-1.0), "duration_s"),
    (dict(duration_s=math.nan), "duration_s"),
    (dict(duration_s=1e-5), "duration_s"),
    (dict(record_interval_s=-1.0), "record_interval_s"),
    (dict(record_interval_s=0.0015), "record_interval_s"),
    (dict(steady_from_cycle=-1), "steady_from_cycle"),
    (dict(params=None), "params"),
    (dict(record_shapes=True), "record_shapes"),
    (dict(arch="tpu"), "arch"),
    (dict(solver="fast"), "solver"),
    # a text would switch an option on ("no" is truthy): a flag takes True or False
    (dict(record_shapes="no", record_interval_s=0.005), r"^record_shapes must be True or False, "
                                                        r"got 'no'$"),
    (dict(progress="yes"), r"^progress must be True or False, got 'yes'$"),
    (dict(progress=0), r"^progress must be True or False, got 0$"),
])
def test_simulate_rejects_bad_arguments(kwargs, match):
    arguments = dict(params=[ts.StarParams()], duration_s=0.01)
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=match):
        ts.simulate(**arguments)


def test_gait_parsing_and_forward_direction():
    assert Gait.parse("A3+A1").actuators == (1, 3)
    assert ts.StarParams(gait="a3+A1").gait == "A1+A3"
    assert Gait.parse("none").actuators == ()
    assert Gait.parse("A1+A8").mask.tolist() == [1, 0, 0, 0, 0, 0, 0, 1]
    np.testing.assert_allclose(Gait.parse("A1+A3").forward, [np.sqrt(0.5), np.sqrt(0.5)])
    assert Gait.parse("A1+A5").forward is None
    assert Gait.parse("none").forward is None


def test_symmetry_classes_partition_the_255_gaits():
    classes = symmetry_classes()
    members = [m for _, group in classes for m in group]
    assert len(classes) == 29
    assert len(members) == len(set(members)) == 255
    for representative, group in classes:
        assert representative in group
        for rotation in range(8):
            for reflect in (False, True):
                assert Gait.parse(representative).transform(rotation, reflect).name in group


def test_default_topology_is_the_papers():
    topology = build_topology(ts.StarParams())
    assert (topology.n_nodes, topology.n_edges, topology.n_triplets) == (193, 200, 192)
    radii = np.hypot(*topology.rest_positions.T)
    assert radii.max() == pytest.approx(0.052)
    # the arcs bulge inwards but stay outside the cylinder (radius 15 mm)
    assert np.sort(radii)[1] > 0.015
    arc = topology.triplet_actuator >= 0
    assert np.all(topology.rest_curvature[arc] < 0)


def test_adaptive_step_bounds_must_be_ordered():
    """dt_min ≤ dt_max, and an adaptive first step dt within [dt_min, dt_max]: each end
    accepted, just past either refused with the bounds named; a fixed step ignores them."""
    with pytest.raises(ValueError, match=r"^dt_min must be <= dt_max .*, got dt_min = 0.01 s and "
                                         r"dt_max = 0.005 s$"):
        ts.SolverConfig(adaptive=True, dt_min=0.01, dt_max=0.005)
    # with fixed steps too, and a dt_max set below the default dt_min is named as well
    with pytest.raises(ValueError, match=r"got dt_min = 1e-06 s and dt_max = 1e-07 s$"):
        ts.SolverConfig(dt_max=1e-7)
    assert ts.SolverConfig(dt_max=1e-6).dt_max == 1e-6   # equal bounds: allowed
    bounds = dict(adaptive=True, dt_min=1e-4, dt_max=0.01)
    assert ts.SolverConfig(dt=1e-4, **bounds).dt == 1e-4
    assert ts.SolverConfig(dt=0.01, **bounds).dt == 0.01
    for dt in (0.01 * (1 + 1e-12), 1e-4 * (1 - 1e-12)):
        with pytest.raises(ValueError, match=r"^dt \(the first adaptive step\) must be in "
                                             r"\[dt_min, dt_max\] = \[0.0001, 0.01\] s, got "):
            ts.SolverConfig(dt=dt, **bounds)
    assert ts.SolverConfig(dt=1e-5, dt_min=1e-4, dt_max=0.01).dt == 1e-5


@pytest.mark.parametrize("field,value", [
    ("damping_time", -1e-3), ("damping_time", math.nan), ("damping_time", 2.0),
    ("joint_stiffness", "rigid"), ("profile_closure", "smooth"), ("alpha", 1e6),
    ("cylinder_diameter", 1e300), ("youngs_modulus", 1e-300), ("actuator_profile", "paper"),
])
def test_new_physics_fields_and_extreme_values_are_refused_naming_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        ts.StarParams(**{field: value})


def test_numpy_scalars_are_accepted_as_numbers():
    params = ts.StarParams(n_arc=np.int64(24), alpha=np.float32(0.5), damping_time=np.float64(1e-3))
    assert params.n_arc == 24 and type(params.n_arc) is int
    assert params.alpha == pytest.approx(0.5) and type(params.alpha) is float
    assert ts.SolverConfig(dt=np.float64(2e-3), max_newton=np.int32(10)).max_newton == 10


def test_a_zero_is_stored_as_positive_zero():
    """-0.0 == 0.0, so two parameters that compare equal must also be the same bits: a zero is
    stored as +0.0 (build_model builds equal instances once and repeats their tables)."""
    from taichi_star.actuation import CurvatureProfile

    negative = ts.StarParams(damping_time=-0.0, linear_drag=-0.0, actuator_delays=(-0.0,) * 8,
                             actuator_profile=CurvatureProfile(cooling=(94.777, 2.507, -0.0,
                                                                         4.445)))
    zeros = [negative.damping_time, negative.linear_drag, *negative.actuator_delays,
             negative.actuator_profile.cooling[2]]
    assert zeros == [0.0] * 11 and all(math.copysign(1.0, z) == 1.0 for z in zeros)
    assert math.copysign(1.0, ts.StarParams(alpha=-0.0).alpha) == 1.0


def test_presets_are_named_models_with_overrides():
    assert ts.StarParams.preset("paper") == ts.StarParams()
    accurate = ts.StarParams.preset("accurate", gait="A1+A2")
    assert (accurate.damping_time, accurate.joint_stiffness, accurate.actuation_ends) == (
        pytest.approx(0.94e-3), "series", "shared")
    assert accurate.gait == "A1+A2"
    assert ts.SolverConfig.preset("paper") == ts.SolverConfig()
    with pytest.raises(ValueError, match="preset"):
        ts.StarParams.preset("fast")


def test_identified_preset_is_its_documented_fields():
    from taichi_star.params import IDENTIFIED_FIELDS
    identified = ts.StarParams.preset("identified", gait="A1+A4")
    assert identified == ts.StarParams(gait="A1+A4", **IDENTIFIED_FIELDS)
    assert identified != ts.StarParams(gait="A1+A4")  # it differs from the paper's model
    # the identified values are fitted, not defaults: every field named differs from its default
    for name, value in IDENTIFIED_FIELDS.items():
        assert getattr(identified, name) == value != getattr(ts.StarParams(), name)
    assert ts.SolverConfig.preset("identified") == ts.SolverConfig()


# The boundaries and messages below are the ranges documented on each field.

@pytest.mark.parametrize("field,value,message", [
    ("max_newton", 0, "max_newton must be an integer in [1, 200], got 0"),
    ("max_newton", 201, "max_newton must be an integer in [1, 200], got 201"),
    ("max_substep_halvings", 11, "max_substep_halvings must be an integer in [0, 10], got 11"),
    ("max_substep_halvings", 2.5, "max_substep_halvings must be an integer in [0, 10], got 2.5"),
    ("dt", 0.0, "dt must be a real number in (0, 0.05], got 0.0"),
    ("dt_min", 0.0, "dt_min must be a real number in (0, 0.05], got 0.0"),
    ("dt_max", 0.0, "dt_max must be a real number in (0, 0.05], got 0.0"),
    ("newton_tol", 2e-6, "newton_tol must be a real number in [1e-14, 1e-06], got 2e-06"),
    ("residual_tol", 2e3, "residual_tol must be a real number in [1e-08, 1000], got 2000.0"),
    ("residual_tol", 0.0, "residual_tol must be a real number in [1e-08, 1000], got 0.0"),
    ("error_tol", 2e-3, "error_tol must be a real number in [1e-12, 0.001], got 0.002"),
])
def test_solver_config_message_names_the_field_its_kind_and_its_range(field, value, message):
    with pytest.raises(ValueError) as error:
        ts.SolverConfig(**{field: value})
    assert str(error.value) == message


@pytest.mark.parametrize("changes", [
    dict(max_newton=1), dict(max_newton=200), dict(max_substep_halvings=0),
    dict(max_substep_halvings=10), dict(newton_tol=1e-14), dict(error_tol=1e-12),
    dict(residual_tol=1e-8), dict(residual_tol=1000.0),
    dict(error_tol=1e-3), dict(dt=0.05, dt_max=0.05),
    # a fixed step may be smaller than the adaptive bounds, which it does not use
    dict(dt=1e-7),
    # an adaptive run may pin its step: dt_min = dt = dt_max
    dict(adaptive=True, dt=2e-3, dt_min=2e-3, dt_max=2e-3),
])
def test_solver_config_accepts_the_ends_of_its_closed_ranges(changes):
    config = ts.SolverConfig(**changes)
    for field, value in changes.items():
        assert getattr(config, field) == value


def test_solver_config_stores_numpy_scalars_as_python_numbers():
    """A definition hash and a JSON manifest see the stored values: the same settings given as
    NumPy scalars must be stored as the same Python numbers."""
    config = ts.SolverConfig(dt=np.float32(0.0025), newton_tol=np.float64(1e-9),
                             max_newton=np.int32(30), max_substep_halvings=np.int64(3),
                             adaptive=np.bool_(True), error_tol=np.float64(1e-6),
                             dt_min=np.float64(1e-5), dt_max=np.float64(0.01))
    expected = {"dt": float, "newton_tol": float, "max_newton": int, "max_substep_halvings": int,
                "adaptive": bool, "error_tol": float, "dt_min": float, "dt_max": float}
    for field, kind in expected.items():
        assert type(getattr(config, field)) is kind, field
    assert config == ts.SolverConfig(dt=float(np.float32(0.0025)), newton_tol=1e-9, max_newton=30,
                                     max_substep_halvings=3, adaptive=True, error_tol=1e-6,
                                     dt_min=1e-5, dt_max=0.01)


@pytest.mark.parametrize("cls,field,choices", [
    (ts.StarParams, "jet_mode", ["contract", "always"]),
    (ts.StarParams, "actuation_ends", ["clamped", "shared"]),
    (ts.StarParams, "joint_stiffness", ["limb", "series"]),
    (ts.StarParams, "profile_closure", ["jump", "ramp"]),
    (ts.StarParams, "actuation_origin", ["profile", "rest"]),
    (ts.StarParams, "jet_direction", ["hub", "normal", "bisector"]),
    (ts.StarParams, "jet_application", ["hub", "spread"]),
    (ts.SolverConfig, "precision", ["f64", "f32"]),
    (ts.SolverConfig, "integrator", ["euler", "bdf2"]),
    (ts.SolverConfig, "jacobian", ["newton", "chord", "lagged"]),
])
def test_a_bad_choice_is_refused_naming_the_field_and_the_choices(cls, field, choices):
    with pytest.raises(ValueError) as error:
        cls(**{field: "other"})
    assert str(error.value) == f"{field} must be one of {choices}, got 'other'"


def test_presets_default_to_the_paper_and_name_the_choices_when_unknown():
    assert ts.StarParams.preset() == ts.StarParams()
    assert ts.SolverConfig.preset() == ts.SolverConfig()
    for cls in (ts.StarParams, ts.SolverConfig):
        with pytest.raises(ValueError) as error:
            cls.preset("fast")
        assert str(error.value) == "preset must be one of ['paper', 'accurate', 'identified'], got 'fast'"


def test_a_profile_that_is_not_a_curvature_profile_is_refused_naming_its_type():
    with pytest.raises(ValueError, match="must be a CurvatureProfile, got str$"):
        ts.StarParams(actuator_profile="paper")


def test_the_period_must_outlast_the_heating_pulse():
    heating = ts.StarParams().actuator_profile.switch_time
    whole_range = (f"period must be a real number in ({heating:g}, 1000] (longer than the "
                   f"heating phase t0), got ")
    # the heating phase's end itself is refused (the range is open there), a hair past it not;
    # a value below the declared (0, 1000] and one inside it but shorter than the heating phase
    # get the same message: the range the profile makes, not only the declared one
    for value in (heating, 0.5 * heating, 0.0, -1.0, 1000.5):
        with pytest.raises(ValueError) as error:
            ts.StarParams(period=value)
        assert str(error.value) == whole_range + repr(float(value))
    # the next double above the end: the open side is the end alone
    above = float(np.nextafter(heating, np.inf))
    assert ts.StarParams(period=above).period == above
    assert ts.StarParams(period=1000.0).period == 1000.0
    beyond = float(np.nextafter(1000.0, np.inf))
    with pytest.raises(ValueError) as error:
        ts.StarParams(period=beyond)
    assert str(error.value) == whole_range + repr(beyond)
    shorter = dataclasses.replace(ts.StarParams().actuator_profile, switch_time=0.05)
    assert ts.StarParams(period=0.1, actuator_profile=shorter).period == 0.1


def test_the_tips_must_lie_beyond_the_joints():
    """The tip radius's range starts at the joint radius (open): at it and below the declared
    0.001 the message states (joint_radius, 2], not the declared [0.001, 2]."""
    joint = ts.StarParams().joint_radius
    for tip in (joint, 5e-4, 2.5):
        with pytest.raises(ValueError) as error:
            ts.StarParams(tip_radius=tip)
        assert str(error.value) == (f"tip_radius must be a real number in ({joint:g}, 2] (beyond "
                                    f"joint_radius: the limbs point outwards), got {tip!r}")
    assert ts.StarParams(tip_radius=2.0).tip_radius == 2.0
    assert ts.StarParams(joint_radius=0.01, tip_radius=0.011).tip_radius == 0.011


def test_joint_radius_is_bounded_by_the_widest_chord_a_rest_arc_spans():
    """Neighbouring joints 45° apart at radius r are a chord 2·r·sin(22.5°) apart; an arc of
    curvature K̄(0) spans at most its diameter 2/K̄(0), so r < 1/(K̄(0)·sin(22.5°))."""
    rest = ts.StarParams().actuator_profile.rest_curvature
    # the bound as the library computes it: the double refused below and the next one down,
    # accepted, pin it to the last bit
    widest = 1.0 / (rest * math.sin(math.pi / 8))
    below = float(np.nextafter(widest, 0.0))
    assert ts.StarParams(joint_radius=below).joint_radius == below
    # the widest itself is refused (open), and so is 1.5 m, inside the declared [0.001, 1]: the
    # message states the range the profile makes, whichever end a value misses
    for radius in (widest, widest * 1.001, 1.5, float(np.nextafter(0.001, 0.0)), 5e-4):
        with pytest.raises(ValueError) as error:
            ts.StarParams(joint_radius=radius)
        assert str(error.value) == (
            f"joint_radius must be a real number in [0.001, {widest:.6g}) (an actuator arc of "
            f"rest curvature {rest:.5g} 1/m cannot span joints further apart), got {radius!r}")
    assert ts.StarParams(joint_radius=0.001, tip_radius=0.05).joint_radius == 0.001


def test_replace_changes_fields_and_validates_again():
    params = ts.StarParams().replace(alpha=0.5, gait="A3+A1")
    assert (params.alpha, params.gait) == (0.5, "A1+A3")
    assert params.replace(alpha=0.8) == ts.StarParams(gait="A1+A3")
    with pytest.raises(ValueError, match="alpha"):
        params.replace(alpha=-1.0)
    solver = ts.SolverConfig().replace(dt=2e-3)
    assert solver.dt == 2e-3 and solver.replace(dt=1e-3) == ts.SolverConfig()
    with pytest.raises(ValueError, match="dt"):
        solver.replace(dt=-1.0)


def test_numeric_fields_are_all_fields_but_the_texts_and_the_profile():
    names = ts.StarParams.field_names()
    assert names[0] == "gait" and len(names) == len(set(names))
    texts = {"gait", "jet_mode", "actuation_ends", "joint_stiffness", "profile_closure",
             "actuator_profile", "jet_direction", "jet_application", "actuation_origin"}
    vectors = set(PER_ACTUATOR_FIELDS)  # one number per actuator
    numeric = ts.StarParams.numeric_field_names()
    assert set(numeric) == set(names) - texts - vectors
    assert len(numeric) == len(names) - len(texts) - len(vectors)
    for name in vectors:
        assert len(getattr(ts.StarParams(), name)) == 8, name
    for name in numeric:
        assert isinstance(getattr(ts.StarParams(), name), (int, float)), name


@pytest.mark.parametrize("cls,typo,suggestion", [
    (ts.StarParams, "alpah", "'alpha'"),
    (ts.StarParams, "drag_perpendicualr", "'drag_perpendicular'"),
    (ts.SolverConfig, "dtt", "'dt'"),
])
def test_a_misspelt_field_is_named_with_a_suggestion_and_the_field_list(cls, typo, suggestion):
    with pytest.raises(TypeError, match=f"{cls.__name__} has no field '{typo}'; did you mean "
                                        f"{suggestion}.*fields: ") as error:
        cls(**{typo: 1})
    assert all(f in str(error.value) for f in ("gait", "alpha", "n_limb")) \
        if cls is ts.StarParams else "max_newton" in str(error.value)


def test_a_word_like_no_field_gets_no_suggestion_and_real_fields_still_work():
    with pytest.raises(TypeError, match=r"StarParams has no field 'zzz' \(fields: gait, "):
        ts.StarParams(zzz=1)
    assert ts.StarParams(alpha=0.5, gait="A1+A2").alpha == 0.5
    assert ts.StarParams("A1+A2", 0.5) == ts.StarParams(gait="A1+A2", alpha=0.5)  # positional


SMALLEST_NORMAL = sys.float_info.min
LARGEST_SUBNORMAL = float(np.nextafter(SMALLEST_NORMAL, 0.0))


@pytest.mark.parametrize("value, refused", [
    (5e-324, True), (LARGEST_SUBNORMAL, True), (SMALLEST_NORMAL, False), (0.0, False),
    # the smallest exponent with mantissa bits: a normal number, kept (an exponent mask one
    # bit short read it as subnormal, unseen by the cases above: a mutation audit, 2026-12)
    (float(np.nextafter(SMALLEST_NORMAL, 1.0)), False)])
def test_a_subnormal_number_is_refused_in_a_field_and_per_actuator(value, refused):
    """Taichi's start makes arithmetic flush subnormal numbers to 0 for the whole process, so
    such a value gave one robot before it and another after (an audit, 2026-12): a value within a
    field's range is refused if subnormal, naming the field (and the actuator); one outside it
    gets the range's message as before. The bound: the largest subnormal refused, the smallest
    normal number kept as it is."""
    cases = {"alpha": lambda x: dict(alpha=x),
             r"actuator_delays\[2\] \(A3\)": lambda x: dict(
                 actuator_delays=(0.0, 0.0, x) + (0.0,) * 5)}
    for name, fields in cases.items():
        if refused:
            with pytest.raises(ValueError, match=f"^{name} must not be a subnormal number"):
                ts.StarParams(**fields(value))
        else:
            built = ts.StarParams(**fields(value))
            assert (built.alpha if "alpha" in name else built.actuator_delays[2]) == value
    with pytest.raises(ValueError, match=r"^alpha must be a real number in \[0, "):
        ts.StarParams(alpha=-5e-324)  # below the range: its message, before Taichi or after
    # the actuators' profile too (its constants were taken as given until 2026-12)
    profiles = {r"CurvatureProfile.cooling\[1\]": ("cooling", (94.777, value, 1.019, 4.445),
                                                    lambda profile: profile.cooling[1]),
                "CurvatureProfile.switch_time": ("switch_time", value,
                                                 lambda profile: profile.switch_time)}
    for name, (field, given, kept) in profiles.items():
        if refused:
            with pytest.raises(ValueError, match=f"^{name} must not be a subnormal number"):
                ts.CurvatureProfile(**{field: given})
        elif value > 0 or field == "cooling":  # a switch time of 0 is refused as not > 0
            assert kept(ts.CurvatureProfile(**{field: given})) == value


def test_a_subnormal_number_is_refused_before_and_after_taichi_starts():
    """The refusal reads the number's bits, which no CPU mode changes: the same in a fresh
    interpreter before Taichi starts and after."""
    script = (
        "import taichi as ti, taichi_star as ts\n"
        "def refused():\n"
        "    try:\n"
        "        ts.StarParams(alpha=5e-324)\n"
        "    except ValueError as error:\n"
        "        return 'subnormal' in str(error)\n"
        "    return False\n"
        "before = refused()\n"
        "ti.init(arch=ti.cpu)\n"
        "tiny = float('1e-160')\n"
        "assert tiny * tiny == 0.0, 'Taichi did not flush subnormals here'\n"
        "print(before, refused())\n")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split()[-2:] == ["True", "True"]


def test_a_single_star_params_is_a_batch_of_one():
    from taichi_star.model import validate_batch
    one = ts.StarParams(gait="A1+A2")
    assert validate_batch(one) == (one,)
    assert validate_batch([one, one]) == (one, one)


def test_a_batch_of_two_topologies_is_refused_naming_both_and_run_batch():
    """One engine is compiled for one mesh: instances of another n_arc or n_limb are refused
    naming each (n_arc, n_limb) found and pointing at run_batch, which groups them."""
    from taichi_star.model import validate_batch
    one = ts.StarParams(gait="A1+A2")
    finer = one.replace(n_arc=one.n_arc + 2)
    with pytest.raises(ValueError, match=re.escape(
            f"got (n_arc, n_limb) in {sorted([one.topology_key, finer.topology_key])}: "
            f"run_batch runs such a batch")):
        validate_batch([one, finer, one])


def test_the_allowed_values_of_a_narrowed_field_state_what_narrows_it_and_its_default_bound():
    """allowed_values (help's table, the API reference) gave the declared [0.001, 1] for
    joint_radius, 40× what the default profile allows (an audit, 2026-12); the narrowing and
    the bound it makes with the default profile are now stated, and that bound is the one
    enforced: just inside it accepted, at it refused."""
    profile = ts.StarParams().actuator_profile
    widest = 1.0 / (profile.rest_curvature * math.sin(math.pi / 8))
    assert ts.allowed_values("joint_radius") == (
        f"[0.001, 1], and below 1/(K̄(0)·sin 22.5°), the widest a rest arc spans "
        f"({widest:.5g} m with the default profile)")
    stated = float(f"{widest:.5g}")
    assert ts.StarParams(joint_radius=stated * 0.9999).joint_radius == stated * 0.9999
    with pytest.raises(ValueError, match="^joint_radius must be"):
        ts.StarParams(joint_radius=stated * 1.0001)
    assert ts.allowed_values("period") == (
        f"(0, 1000], and longer than the profile's heating phase t0 ({profile.switch_time:g} s by "
        f"default)")
    assert ts.allowed_values("tip_radius") == "[0.001, 2], and beyond joint_radius"
    assert ts.allowed_values("hub_height").startswith("[0, 0.5], and 0 (off) or at least 0.001")
    assert ts.allowed_values("alpha") == "[0, 10]"   # a field nothing narrows: the declared range


def test_a_profile_that_leaves_a_field_no_value_is_named_as_the_cause():
    """The period's range starts at the profile's t0 and the joint radius's ends at the widest
    chord of its rest arc; where that leaves nothing ("(2000, 1000]" had been the message, naming
    the period), the profile is refused. t0 at the period's top, 1000 s, leaves nothing (the
    period must exceed t0); a hair below it leaves 1000 s itself."""
    for switch_time in (2000.0, 1000.0):
        profile = ts.CurvatureProfile(switch_time=switch_time)
        with pytest.raises(ValueError) as error:
            ts.StarParams(actuator_profile=profile)
        assert str(error.value) == (f"actuator_profile leaves period no value in its declared "
                                    f"(0, 1000]: its heating phase t0 = {switch_time:g} s "
                                    f"outlasts every period")
    late = ts.CurvatureProfile(switch_time=999.9)
    assert ts.StarParams(actuator_profile=late, period=1000.0).period == 1000.0
    # K̄(0) = 5000 1/m: a rest arc 0.2 mm across spans joints 0.52 mm from the centre at most
    tight = ts.CurvatureProfile(heating=(-89.827, 62.724, 0.061, 5000.0))
    widest = 1.0 / (tight.rest_curvature * math.sin(math.pi / 8))
    with pytest.raises(ValueError) as error:
        ts.StarParams(actuator_profile=tight)
    assert str(error.value) == (f"actuator_profile leaves joint_radius no value in its declared "
                                f"[0.001, 1]: a rest arc of its K̄(0) = "
                                f"{tight.rest_curvature:.5g} 1/m spans joints at most "
                                f"{widest:.3g} m from the centre")


CROSS_CONSTRAINED = {"period", "joint_radius", "tip_radius", "hub_height", "foam_height",
                     "actuator_height"}
"""Fields whose declared range is narrowed by another field (tested on their own: the radii,
the period beyond the heating time, the component heights all set or all off)."""


@pytest.mark.parametrize("name", sorted(set(ts.STAR_RANGES) - CROSS_CONSTRAINED))
def test_every_declared_range_is_the_validated_range_at_both_ends(name):
    """The range declared with a field is what __post_init__ enforces: both ends accepted
    (the lowest only where it is included), just beyond either end refused naming the field."""
    from dataclasses import fields

    lowest, highest, included = ts.STAR_RANGES[name]
    integer = isinstance({f.name: f for f in fields(ts.StarParams)}[name].default, int)
    beyond = 1 if integer else max(abs(highest), 1.0) * 1e-9
    assert getattr(ts.StarParams(**{name: highest}), name) == highest
    with pytest.raises(ValueError, match=name):
        ts.StarParams(**{name: highest + beyond})
    if included:
        assert getattr(ts.StarParams(**{name: lowest}), name) == lowest
    else:
        with pytest.raises(ValueError, match=name):
            ts.StarParams(**{name: lowest})
    below = lowest - (1 if integer else max(abs(lowest), 1.0) * 1e-9)
    with pytest.raises(ValueError, match=name):
        ts.StarParams(**{name: below})


def test_help_lists_every_field_with_its_declared_unit_and_allowed_values():
    from dataclasses import fields

    doc = ts.StarParams.__doc__
    for f in fields(ts.StarParams):
        [row] = [line for line in doc.splitlines() if line.strip().startswith(f"| {f.name} |")]
        if f.name in ts.STAR_RANGES:
            lowest, highest, included = ts.STAR_RANGES[f.name]
            unit = PARAMETER_UNITS[f.name]
            narrowed = f", and {f.metadata['narrowed_by']}" if "narrowed_by" in f.metadata else ""
            assert (f"| {unit} | {'[' if included else '('}{lowest:g}, {highest:g}]{narrowed} |"
                    in row)
        elif "choices" in f.metadata:
            assert all(f'"{choice}"' in row for choice in f.metadata["choices"])


def test_jet_inflow_has_its_range_and_needs_the_contract_mode():
    """[0, 10], 0 included (the paper's model); refused with jet_mode "always", whose literal
    formula already jets while a space opens."""
    with pytest.raises(ValueError) as error:
        ts.StarParams(jet_inflow=-0.5)
    assert str(error.value) == "jet_inflow must be a real number in [0, 10], got -0.5"
    assert ts.StarParams(jet_inflow=0.0, jet_mode="always").jet_inflow == 0.0
    assert ts.StarParams(jet_inflow=10.0).jet_inflow == 10.0
    with pytest.raises(ValueError, match="jet_inflow must be 0 with jet_mode 'always'"):
        ts.StarParams(jet_inflow=0.5, jet_mode="always")


def test_jet_variant_fields_are_set_by_name_and_survive_a_csv_row(tmp_path):
    """The fields a model-selection study sets by name (StarParams(**fields), replace) come
    back from a table row read from a CSV, the inflow with its unit column."""
    import dataclasses

    import pandas as pd

    fields = {"jet_direction": "bisector", "jet_application": "spread", "jet_inflow": 0.35,
              "hub_height": 0.05, "foam_height": 0.024, "actuator_height": 0.01}
    params = [ts.StarParams(gait="A1+A4", **fields),
              dataclasses.replace(ts.StarParams(), jet_direction="normal"), ts.StarParams()]
    assert ts.StarParams.columns()["jet_inflow"] == "jet_inflow"  # dimensionless: no suffix
    assert ts.StarParams.columns()["hub_height"] == "hub_height_m"
    table = pd.DataFrame([{column: getattr(p, name) for name, column in
                           ts.StarParams.columns().items()} for p in params])
    path = tmp_path / "rows.csv"
    table.to_csv(path, index=False)
    back = pd.read_csv(path)
    assert [ts.StarParams.from_row(row) for _, row in back.iterrows()] == params


def test_component_heights_are_all_off_or_all_in_their_range():
    """0 = off (the default, ratios exactly 1); a set height is in [1 mm, 0.5 m] and the other
    two must be set with it."""
    assert ts.StarParams().height_ratios == (1.0, 1.0)
    paper_robot = ts.StarParams(hub_height=0.05, foam_height=0.024, actuator_height=0.001)
    assert paper_robot.height_ratios == (0.024 / 0.05, 0.001 / 0.05)
    with pytest.raises(ValueError) as error:
        ts.StarParams(foam_height=0.0009, hub_height=0.05, actuator_height=0.01)
    assert str(error.value) == "foam_height must be 0 (off) or in [0.001, 0.5] m, got 0.0009"
    with pytest.raises(ValueError) as error:
        ts.StarParams(hub_height=0.05)
    assert str(error.value) == ("foam_height, actuator_height must be in [0.001, 0.5] m as "
                                "well: the component heights are all set or all 0 (off)")
    assert ts.StarParams(hub_height=0.5, foam_height=0.001, actuator_height=0.5).hub_height == 0.5


def test_identified_preset_equals_the_committed_study_result():
    """IDENTIFIED_FIELDS are the identified.csv of the committed continued fit that fits the
    training cycles best among its seeds (results/model_select_continued/seed*/), to the 10
    significant digits the preset keeps (so rtol 1e-9), field by field; and that fit started
    at the model selection run's rank-1 point (results/model_select/identified.csv)."""
    import ast
    import json
    from pathlib import Path

    import pandas as pd

    from taichi_star.params import IDENTIFIED_FIELDS

    results = Path(__file__).resolve().parents[2] / "results"
    runs = sorted((results / "model_select_continued").glob("seed*"))
    assert len(runs) == 3
    train = [pd.read_csv(run / "model_select.csv").set_index("stage").loc["refine",
                                                                          "train_objective"]
             for run in runs]
    best = runs[int(np.argmin(train))]
    table = pd.read_csv(best / "identified.csv")
    assert set(table["field"]) == set(IDENTIFIED_FIELDS)
    for field, text in zip(table["field"], table["value"]):
        value = ast.literal_eval(str(text))
        assert np.asarray(IDENTIFIED_FIELDS[field]) == pytest.approx(np.asarray(value), rel=1e-9)
    start = json.loads((best / "identified.csv.json").read_text())["details"]["start"]
    assert start["file"] == "results/model_select/identified.csv"
    started = pd.read_csv(results / "model_select" / "identified.csv")
    for field, text in zip(started["field"], started["value"]):
        assert np.asarray(start["fields"][field]) == pytest.approx(
            np.asarray(ast.literal_eval(str(text))), rel=1e-15)


def test_a_choice_field_given_an_array_or_a_list_names_the_field():
    """`in` on an array compares element-wise (NumPy's "truth value ... is ambiguous" was the
    message); a list of words is not a word either."""
    for value in (np.array(["contract", "always"]), ["contract"], None, 3):
        with pytest.raises(ValueError) as error:
            ts.StarParams(jet_mode=value)
        assert str(error.value) == f"jet_mode must be one of ['contract', 'always'], got {value!r}"


# ---- moved from the model tests: no engine is built ------------------------------------------

@pytest.mark.parametrize("changes,message", [
    ({"actuator_gains": (1.0,) * 3}, r"actuator_gains must have 8 entries \(A1..A8\), got 3"),
    ({"actuator_gains": (1.0,) * 9}, r"actuator_gains must have 8 entries \(A1..A8\), got 9"),
    ({"actuator_gains": (1, 1, -0.1, 1, 1, 1, 1, 1)}, r"actuator_gains\[2\] \(A3\) must be a real "
                                                      r"number in \[0, 5\]"),
    ({"actuator_gains": (1, 1, 1, 1, 1, 1, 1, 5.000001)}, r"actuator_gains\[7\] \(A8\)"),
    ({"actuator_gains": (1, float("nan"), 1, 1, 1, 1, 1, 1)}, r"actuator_gains\[1\]"),
    ({"actuator_gains": (1, True, 1, 1, 1, 1, 1, 1)}, r"actuator_gains\[1\]"),
    ({"actuator_gains": 1.0}, "actuator_gains must be a tuple of 8 numbers"),
    ({"actuator_delays": (0, 0, 0, 0, 0, 0, 0, -1e-9)}, r"actuator_delays\[7\] \(A8\) must be a "
                                                        r"real number in \[0, 3.15\)"),
    ({"actuator_delays": (3.15, 0, 0, 0, 0, 0, 0, 0)}, r"actuator_delays\[0\] \(A1\)"),
    ({"period": 0.5, "actuator_delays": (0, 0.5, 0, 0, 0, 0, 0, 0)}, r"in \[0, 0.5\)"),
    ({"linear_drag": -1.0}, r"linear_drag must be a real number in \[0, 10000\]"),
    ({"hub_linear_drag": 1001.0}, r"hub_linear_drag must be a real number in \[0, 1000\]"),
])
def test_extension_fields_refuse_values_out_of_range(changes, message):
    with pytest.raises(ValueError, match=message):
        ts.StarParams(**changes)


def test_extension_fields_accept_their_bounds_lists_and_arrays():
    params = ts.StarParams(actuator_gains=[0, 5, 1, 1, 1, 1, 1, 1],
                           actuator_delays=np.array([0.0, 3.1499, 0, 0, 0, 0, 0, 0]),
                           linear_drag=1e4, hub_linear_drag=0.0)
    assert params.actuator_gains == (0.0, 5.0, 1.0, 1.0, 1.0, 1.0, 1.0, 1.0)
    assert all(type(v) is float for v in params.actuator_gains + params.actuator_delays)
    assert params.actuator_delays[1] == 3.1499
    hash(params)  # frozen and hashable: usable as a key of a batch or a cache


def test_f32_refuses_robots_it_cannot_resolve_before_any_compute(monkeypatch):
    """2-m limbs need newton_tol >= 3.8e-6 m in f32 (over the 1e-6 m allowed: refused, naming
    newton_tol and tip_radius); 1-mm joints with 10-cm limbs make the size 2,351 times the
    shortest edge (12× off in f32 when run: refused, naming the fields)."""
    def forbidden(*args, **kwargs):
        raise AssertionError("an engine was built for a refused batch")
    # simulate and Simulator both build their model through sensitivities.replica_model
    monkeypatch.setattr("taichi_star.sensitivities.build_model", forbidden)
    f32 = ts.SolverConfig(precision="f32", newton_tol=1e-6)
    large = ts.StarParams(gait="A1+A2", joint_radius=1e-3, tip_radius=2.0)
    with pytest.raises(ValueError, match=r"newton_tol must be >= 3.8e-06 m with precision 'f32' "
                                         r"for params\[1\] .*tip_radius 2 m.*precision 'f64'"):
        ts.simulate([ts.StarParams(), large], 0.3, f32)
    with pytest.raises(ValueError, match=r"newton_tol must be >= 9.5e-07 m .*got 1e-07: use a "
                                         r"newton_tol in \[9.5e-07, 1e-06\] m"):
        ts.Simulator([ts.StarParams(tip_radius=0.5)], f32.replace(newton_tol=1e-7))
    tiny_joints = ts.StarParams(joint_radius=1e-3, tip_radius=0.1)
    with pytest.raises(ValueError, match=r"cannot resolve params\[0\]: its tip_radius 0.1 m is "
                                         r"2351 times its shortest rest edge"):
        ts.simulate([tiny_joints], 0.3, f32)
    # the same batches run in f64
    ts.params.check_precision([large, tiny_joints], ts.SolverConfig())


def test_per_actuator_text_reads_back_as_tables_write_it():
    """Result tables hold a per-actuator tuple as its text; parentheses, brackets or none, spaces
    and a trailing comma read back; anything else names the field and the text."""
    for text in ("(1.0, 0.5, 1, 1, 1, 1, 1, 2.5)", "[1.0,0.5,1,1,1,1,1,2.5]",
                 " 1.0, 0.5, 1, 1, 1, 1, 1, 2.5, "):
        assert ts.StarParams(actuator_gains=text).actuator_gains == (
            1.0, 0.5, 1.0, 1.0, 1.0, 1.0, 1.0, 2.5)
    for text in ("(1.0, 0.5", "1.0; 0.5", "(a, b)"):
        with pytest.raises(ValueError) as error:
            ts.StarParams(actuator_gains=text)
        assert str(error.value) == (f"actuator_gains: cannot read {text!r} as 8 numbers")
    # a long text is quoted by its first 60 characters
    long = "(" + "x, " * 40 + ")"
    with pytest.raises(ValueError) as error:
        ts.StarParams(actuator_gains=long)
    assert str(error.value) == f"actuator_gains: cannot read {long[:60]!r} as 8 numbers"
    with pytest.raises(ValueError, match=r"^actuator_delays must have 8 entries \(A1..A8\), "
                                         r"got 2$"):
        ts.StarParams(actuator_delays="(0, 0.5)")


def test_from_row_reads_every_field_back_and_takes_overrides():
    """A row of a result table (column names with units, the profile and the per-actuator
    tuples as text, NumPy scalars) gives the StarParams back exactly; overrides replace a
    column (which then need not be there); a missing column is named."""
    params = ts.StarParams(gait="A1+A2", alpha=0.1 + 0.2, actuator_gains=(1.0, 0.3, 1, 1, 1, 1, 1, 2),
                           actuator_delays=(0.0, 1 / 3, 0, 0, 0, 0, 0, 0),
                           actuator_profile=ts.CurvatureProfile(switch_time=0.15))
    row = {}
    for name, column in ts.StarParams.columns().items():
        value = getattr(params, name)
        if name == "actuator_profile":
            value = value.to_text()
        elif isinstance(value, tuple):
            value = str(value)
        elif isinstance(value, float):
            value = np.float64(value)
        row[column] = value
    back = ts.StarParams.from_row(row)
    assert back == params and type(back.alpha) is float
    assert ts.StarParams.from_row(row, alpha=0.5) == params.replace(alpha=0.5)
    del row["alpha"]
    assert ts.StarParams.from_row(row, alpha=0.5).alpha == 0.5
    with pytest.raises(ValueError, match=r"^row has no column 'alpha' \(StarParams field "
                                         r"'alpha'\)$"):
        ts.StarParams.from_row(row)
    row["alpha"] = 0.8
    row["actuator_profile"] = "paper"
    with pytest.raises(ValueError, match=r"^actuator_profile: 'paper' is not a profile's text"):
        ts.StarParams.from_row(row)


@pytest.mark.parametrize("changes", [{}, dict(joint_radius=1e-3, tip_radius=0.1),
                                     dict(n_limb=40, tip_radius=0.03), dict(n_arc=40)])
def test_the_shortest_rest_edge_is_the_rest_shapes(changes):
    """f32's check estimates the shortest edge of the rest shape (an arc edge by the arc's
    length over n_arc, the geometry's edge its chord: 1e-3 relative covers that for arcs of
    45° cut in 6 or more); the cases make the arc's, then a limb's edge the shortest."""
    from taichi_star.geometry import build_topology
    from taichi_star.params import shortest_rest_edge

    params = ts.StarParams(**changes)
    assert shortest_rest_edge(params) == pytest.approx(
        build_topology(params).rest_length.min(), rel=1e-3)


def test_f32s_refusals_at_their_boundaries():
    """newton_tol exactly at the floor (32 f32 roundings of the tip radius) is accepted, a hair
    under refused; the advice names the tolerance range while the floor is at most 1e-6 m; a
    robot exactly 320 times its shortest edge runs, a hair more is refused."""
    from taichi_star.params import (F32_MAX_SIZE_TO_EDGE, F32_TOLERANCE_ROUNDOFFS,
                                    F32_UNIT_ROUNDOFF, check_precision, shortest_rest_edge)

    params = ts.StarParams(tip_radius=0.4)   # 302 times its shortest edge: resolvable
    floor = F32_TOLERANCE_ROUNDOFFS * F32_UNIT_ROUNDOFF * params.tip_radius
    check_precision([params], ts.SolverConfig(precision="f32", newton_tol=floor))
    with pytest.raises(ValueError, match=r"use a newton_tol in \[7.6e-07, 1e-06\] m$"):
        check_precision([params], ts.SolverConfig(precision="f32", newton_tol=floor * 0.999))
    # the largest tip radius whose floor is 1e-6 m still gets the range advice
    at_limit = ts.StarParams(tip_radius=1e-6 / (F32_TOLERANCE_ROUNDOFFS * F32_UNIT_ROUNDOFF))
    with pytest.raises(ValueError, match=r"use a newton_tol in \[1e-06, 1e-06\] m$"):
        check_precision([at_limit], ts.SolverConfig(precision="f32", newton_tol=9e-7))
    beyond = ts.StarParams(tip_radius=at_limit.tip_radius * 1.01)
    with pytest.raises(ValueError, match=r"got 1e-06: use precision 'f64'$"):
        check_precision([beyond], ts.SolverConfig(precision="f32", newton_tol=1e-6))
    small = ts.StarParams(joint_radius=0.004)
    edge = shortest_rest_edge(small)
    size = F32_MAX_SIZE_TO_EDGE * edge
    f32 = ts.SolverConfig(precision="f32", newton_tol=1e-6)
    check_precision([small.replace(tip_radius=size)], f32)
    with pytest.raises(ValueError, match=r"^precision 'f32' cannot resolve params\[0\]"):
        check_precision([small.replace(tip_radius=size * (1 + 1e-12))], f32)


def test_a_rest_shape_below_f64s_rounding_is_refused_before_it_is_built():
    """A limb edge of one ulp (tip_radius = joint_radius × (1 + 1e-15)) made the rest curvature
    0/0, NaN, with NumPy's bare warnings, and × (1 + 1e-13) ran "ok" (an audit, 2026-12): in
    f64 a robot more than F64_MAX_SIZE_TO_EDGE (the f32 bound's share of rounding, 1.7e11)
    times its shortest rest edge is refused naming the instance and the fields, before any
    warning; a thousandth under the bound passes the check, a thousandth over is refused
    (the limb edge's own rounding is ~4e-6 of it). The finest meshes the ranges allow stay far
    under it (n_arc 1000 on a 1-mm joint radius: 6.7e4)."""
    from taichi_star.params import (F32_MAX_SIZE_TO_EDGE, F32_UNIT_ROUNDOFF,
                                    F64_MAX_SIZE_TO_EDGE, check_precision, shortest_rest_edge)

    assert F64_MAX_SIZE_TO_EDGE == F32_MAX_SIZE_TO_EDGE * F32_UNIT_ROUNDOFF / 2.0 ** -53
    f64 = ts.SolverConfig()
    base = ts.StarParams()
    for share, refused in ((1 - 1e-3, False), (1 + 1e-3, True)):
        robot = base.replace(tip_radius=base.joint_radius
                             * (1 + base.n_limb / (F64_MAX_SIZE_TO_EDGE * share)))
        ratio = robot.tip_radius / shortest_rest_edge(robot)
        assert (ratio > F64_MAX_SIZE_TO_EDGE) is refused
        if refused:
            with pytest.raises(ValueError, match=r"^precision 'f64' cannot resolve params\[1\]: "
                                                 r"its tip_radius 0\.024 m is 1\.72e\+11 times "
                                                 r"its shortest rest edge"):
                check_precision([base, robot], f64)
        else:
            check_precision([base, robot], f64)
    degenerate = base.replace(tip_radius=base.joint_radius * (1 + 1e-15))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match=r"lengthen that edge \(a tip_radius further beyond "
                                             r"joint_radius, fewer n_limb or n_arc\)$"):
            ts.simulate([degenerate], 0.002, progress=False)
    fine = ts.StarParams(joint_radius=1e-3, n_arc=1000)
    assert 6e4 < fine.tip_radius / shortest_rest_edge(fine) < 7e4
    check_precision([fine], f64)


@pytest.mark.parametrize("cls, field, value", [
    (ts.StarParams, "alpha", 10 ** 400), (ts.StarParams, "alpha", -(10 ** 400)),
    (ts.StarParams, "n_arc", 10 ** 400), (ts.SolverConfig, "dt", 10 ** 400),
    (ts.SolverConfig, "max_newton", 10 ** 400),
    (ts.StarParams, "actuator_gains", (10 ** 400,) + (1.0,) * 7),
    (ts.StarParams, "actuator_delays", (0.0,) * 7 + (10 ** 400,)),
], ids=["alpha", "minus alpha", "n_arc", "dt", "max_newton", "a gain", "a delay"])
def test_an_integer_beyond_floats_range_is_refused_naming_the_field(cls, field, value):
    """An integer past float's range (10**400) was an OverflowError naming no field (its
    conversion to float came before the range test), and in the CLI a traceback with exit
    status 1 (an audit, 2026-12): it is out of range like any other value, its digits
    counted rather than printed."""
    with pytest.raises(ValueError, match=f"^{field}(\\[\\d\\] \\(A\\d\\))? must be .* got an "
                                         f"integer of 401 digits$"):
        cls(**{field: value})


def test_a_joint_radius_just_under_its_bound_builds_a_half_circle_arc():
    """Just under its open bound joint_radius makes each rest arc a half circle, its radius
    the half chord; the 3 nearest allowed values made the difference of their squares a few
    ulps negative and simulate failed with a bare "math domain error" (an audit, 2026-12);
    the topology is built, every node finite."""
    rest = ts.StarParams().actuator_profile.rest_curvature
    widest = 1.0 / (rest * math.sin(math.radians(22.5)))
    radius = widest
    for _ in range(3):
        radius = math.nextafter(radius, 0.0)
        topology = build_topology(ts.StarParams(joint_radius=radius, tip_radius=0.2))
        assert np.isfinite(topology.rest_positions).all()


@pytest.mark.parametrize("name", sorted(SOLVER_RANGES))
def test_every_declared_solver_range_is_the_validated_range_at_both_ends(name):
    """SolverConfig's ranges are declared once with their fields (they were literals in
    __post_init__, again in the docstrings: a review, 2026-12): both ends accepted (the lowest
    only where it is included), one ulp beyond either end refused naming the field. dt_min
    goes with the largest dt_max and dt_max with a dt_min of 1e-300 s, so that their ordering
    rule holds at every end."""
    lowest, highest, included = SOLVER_RANGES[name]
    integer = isinstance(ts.SolverConfig.__dataclass_fields__[name].default, int)

    def config(value):
        paired = {"dt_min": {"dt_max": ts.params.MAX_DT}, "dt_max": {"dt_min": 1e-300}}
        return ts.SolverConfig(**{name: value, **paired.get(name, {})})

    def beyond(end, direction):
        return end + direction if integer else math.nextafter(end, direction * math.inf)

    assert getattr(config(highest), name) == highest
    with pytest.raises(ValueError, match=f"^{name} must be"):
        config(beyond(highest, 1))
    if included:
        assert getattr(config(lowest), name) == lowest
    else:
        with pytest.raises(ValueError, match=f"^{name} must be"):
            config(lowest)
    with pytest.raises(ValueError, match=f"^{name} must be"):
        config(beyond(lowest, -1))


def test_a_float32_past_a_bound_as_a_float_is_refused_saying_what_it_became():
    """np.float32(0.05) is 0.05000000074505806 as the float it would be stored as, past dt's
    bound of 0.05: refused (it was stored, past MAX_DT), and the message says what it became
    (it read "got np.float32(0.05)", a value in range: a review, 2026-12); float32 values that
    stay within the range are taken as their floats."""
    with pytest.raises(ValueError, match=r"^dt must be a real number in \(0, 0\.05\], got "
                                         r"np\.float32\(0\.05\) \(0\.05000000074505806 as a "
                                         r"float\)$"):
        ts.SolverConfig(dt=np.float32(0.05))
    assert ts.SolverConfig(dt=np.float32(0.04)).dt == float(np.float32(0.04))


@pytest.mark.parametrize("name", sorted(set(SOLVER_RANGES) - {"residual_tol", "newton_tol"}))
def test_none_is_refused_where_it_is_not_the_default(name):
    """None switches residual_tol's test off and gives newton_tol its precision's default, and
    is no value of any other numeric field (the first form of the declared ranges let None
    through for all of them: caught by the hypothesis test of bad solver fields)."""
    with pytest.raises(ValueError, match=f"^{name} must be .* got None$"):
        ts.SolverConfig(**{name: None})
    assert ts.SolverConfig(residual_tol=None).residual_tol is None
    assert ts.SolverConfig(newton_tol=None).newton_tol == 1e-10


def test_the_joint_radius_keeps_its_declared_top_when_the_profile_allows_more():
    """A profile of small rest curvature (K̄(0) ≈ 0.99 1/m: its arc bound 2.6 m) replaced the
    declared top of 1 m instead of narrowing it, so 1.5 m was taken (an audit, 2026-12): the
    smaller bound holds, the declared top itself accepted, a hair above refused with the
    declared range; the paper's profile (arc bound 0.18 m) still narrows it."""
    flat = ts.CurvatureProfile(heating=(-0.5, 62.724, 0.061, 1.0))
    assert ts.StarParams(actuator_profile=flat, joint_radius=1.0, tip_radius=1.5).joint_radius \
        == 1.0
    with pytest.raises(ValueError, match=r"^joint_radius must be a real number in \[0.001, 1\], "
                                         r"got 1.0000001$"):
        ts.StarParams(actuator_profile=flat, joint_radius=1.0000001, tip_radius=1.5)
    with pytest.raises(ValueError, match=r"cannot span joints further apart"):
        ts.StarParams(joint_radius=0.5, tip_radius=0.6)


def test_a_per_actuator_range_declared_once_is_the_one_checked_and_shown():
    """The gains' and delays' ranges were written three times (the field's words, the check,
    the sensitivity check's kink): now declared with the field; the check, its words and the
    table read that one declaration, the delays' top from the period of the same robot."""
    assert PER_ACTUATOR_RANGES == {"actuator_gains": (0.0, 5.0, True),
                                   "actuator_delays": (0.0, "period", False)}
    assert allowed_values("actuator_gains") == "8 numbers in [0, 5]"
    assert allowed_values("actuator_delays") == "8 numbers in [0, period)"
    # each end: the gains' top included, the delays' (the robot's own period) excluded
    assert ts.StarParams(actuator_gains=(5.0,) * 8).actuator_gains == (5.0,) * 8
    with pytest.raises(ValueError, match=r"^actuator_gains\[0\] \(A1\) must be a real number "
                                         r"in \[0, 5\], got 5.000000000000001$"):
        ts.StarParams(actuator_gains=(float(np.nextafter(5.0, 6.0)),) * 8)
    below = float(np.nextafter(2.0, 0.0))
    assert ts.StarParams(period=2.0, actuator_delays=(below,) * 8).actuator_delays[0] == below
    with pytest.raises(ValueError, match=r"^actuator_delays\[7\] \(A8\) must be a real number "
                                         r"in \[0, 2\), got 2.0$"):
        ts.StarParams(period=2.0, actuator_delays=(0.0,) * 7 + (2.0,))
    with pytest.raises(ValueError, match=r"^actuator_delays\[0\] \(A1\) must be a real number "
                                         r"in \[0, 2\), got -5e-324$"):
        ts.StarParams(period=2.0, actuator_delays=(-5e-324,) + (0.0,) * 7)
