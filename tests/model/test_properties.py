"""Property-based input hardening tests, with hypothesis.

- Random valid StarParams batches (physically reasonable ranges, the paper's topology so that
  every example reuses one compiled engine) simulate a few steps without an exception, with a
  valid status per instance and finite results where the status is ok.
- Random invalid values of every StarParams / SolverConfig field (NaN, ±inf, negative, zero
  where not allowed, wrong types, unknown or repeated gait actuators, non-integer n_arc/n_limb)
  raise a ValueError whose message names the field.
- Invalid `simulate` arguments (duration ≤ 0 or not finite, record_interval_s < 0 or not finite,
  an empty batch, mixed topologies, unknown arch, bad worker counts) raise a ValueError naming
  the argument.
- One exact invariance of the model: every mass and force coefficient × λ with α × √λ leaves
  the path as it was (which parameter combinations no swimming data can fix).

Few examples each (the simulations dominate: ~10 batches of ≤ 8 robots × ≤ 5 steps) and no
deadline (the first example compiles the engine).
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import taichi_star as ts
from taichi_star import params as params_module
from taichi_star.actuation import CurvatureProfile
from taichi_star.gait import Gait

SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow])
FAST = settings(max_examples=60, **SETTINGS)
"""The invalid-input properties raise before any compute: cheap, so more examples."""
SLOW = settings(max_examples=8, **SETTINGS)
"""Valid batches compile an engine per integrator and term set: few examples."""

LARGEST_JOINT_RADIUS = 1.0 / (CurvatureProfile().rest_curvature * math.sin(math.pi / 8))
"""≈ 25.6 mm: an arc of the rest curvature cannot span joints further apart (params.py)."""


# ----------------------------------------------------------------------------- strategies

def _log_uniform(low, high):
    return st.floats(math.log(low), math.log(high)).map(math.exp)


@st.composite
def gaits(draw):
    """A non-empty set of actuators in random order, e.g. "A3+A1", or "none"."""
    actuators = draw(st.lists(st.integers(1, 8), min_size=0, max_size=8, unique=True))
    return "+".join(f"A{m}" for m in actuators) if actuators else "none"


@st.composite
def valid_params(draw):
    """StarParams with every (known) field drawn from a physically reasonable range around the
    paper's values: stiffness over three decades, fluid coefficients from small to several times
    the paper's, geometry ±~40 %, every option. The topology stays the paper's."""
    joint_radius = draw(st.floats(0.015, 0.95 * LARGEST_JOINT_RADIUS))
    values = dict(
        gait=draw(gaits()),
        alpha=draw(st.floats(0.05, 2.0)),
        # no subnormal numbers: StarParams refuses them (flushed to 0 once Taichi has started)
        added_mass_coeff=draw(st.floats(0.0, 5.0, allow_subnormal=False)),
        youngs_modulus=draw(_log_uniform(5e5, 5e8)),
        limb_stiffness_ratio=draw(_log_uniform(1.0, 1000.0)),
        drag_parallel=draw(st.floats(1e-3, 0.1)),
        drag_perpendicular=draw(st.floats(0.05, 3.0)),
        cylinder_drag=draw(st.floats(0.5, 50.0)),
        period=draw(st.floats(0.2, 5.0)),
        jet_mode=draw(st.sampled_from(params_module.JET_MODES)),
        thickness=draw(st.floats(2e-3, 5e-3)),
        actuator_density=draw(st.floats(1000.0, 4000.0)),
        foam_density=draw(st.floats(200.0, 1500.0)),
        fluid_density=draw(st.floats(800.0, 1200.0)),
        cylinder_mass_per_height=draw(st.floats(0.3, 3.0)),
        cylinder_diameter=draw(st.floats(0.015, 0.04)),
        cylinder_added_mass_coeff=draw(st.floats(0.0, 2.0, allow_subnormal=False)),
        joint_radius=joint_radius,
        tip_radius=joint_radius + draw(st.floats(0.015, 0.04)),
    )
    values["actuation_ends"] = draw(st.sampled_from(params_module.ACTUATION_ENDS))
    values["joint_stiffness"] = draw(st.sampled_from(params_module.JOINT_STIFFNESSES))
    values["profile_closure"] = draw(st.sampled_from(("jump", "ramp")))
    # every term present (one compiled engine per integrator; compile-out is tested apart)
    values["damping_time"] = draw(st.floats(1e-5, 5e-3))
    return ts.StarParams(**values)


POSITIVE = ["youngs_modulus", "limb_stiffness_ratio", "period", "thickness", "actuator_density",
            "foam_density", "fluid_density", "cylinder_mass_per_height", "cylinder_diameter",
            "joint_radius", "tip_radius"]
NON_NEGATIVE = ["alpha", "added_mass_coeff", "drag_parallel", "drag_perpendicular",
                "cylinder_drag", "cylinder_added_mass_coeff"]
NOT_A_REAL = st.sampled_from([math.nan, math.inf, -math.inf, "1.0", None, True, [1.0], 1j])


@st.composite
def invalid_star_field(draw):
    """(field, value) with a value StarParams must reject, naming the field."""
    kind = draw(st.sampled_from(["positive", "non_negative", "gait", "jet_mode", "int",
                                 "above_range"]))
    if kind == "above_range":
        # orders of magnitude beyond any real robot: refused with the range named
        field = draw(st.sampled_from(sorted(set(params_module.STAR_RANGES) - {"n_arc", "n_limb"})))
        highest = params_module.STAR_RANGES[field][1]
        value = draw(st.floats(highest * 1.001, 1e300))
    elif kind == "positive":
        field = draw(st.sampled_from(POSITIVE))
        value = draw(st.one_of(NOT_A_REAL, st.just(0.0), st.just(0),
                               st.floats(max_value=0.0, allow_nan=False, allow_infinity=False)))
    elif kind == "non_negative":
        field = draw(st.sampled_from(NON_NEGATIVE))
        value = draw(st.one_of(NOT_A_REAL, st.floats(max_value=-1e-300, allow_nan=False,
                                                     allow_infinity=True)))
    elif kind == "gait":
        field = "gait"
        actuators = draw(st.lists(st.integers(1, 8), min_size=1, max_size=4))
        repeated = actuators + [draw(st.sampled_from(actuators))]
        value = draw(st.one_of(
            st.just("+".join(f"A{m}" for m in repeated)),            # duplicated actuator
            st.integers(0, 99).filter(lambda m: not 1 <= m <= 8).map(lambda m: f"A{m}"),
            st.sampled_from(["", "A", "B1", "A1+", "+A1", "A1++A2", "A1 A2", "a1x", "A-1",
                             "A1+B2"]),
            st.sampled_from([1, 1.0, None, ["A1"], ("A1",)])))       # not a string
    elif kind == "jet_mode":
        field = "jet_mode"
        value = draw(st.one_of(st.text(max_size=8).filter(
            lambda s: s not in params_module.JET_MODES), st.sampled_from([None, 1])))
    else:
        field = draw(st.sampled_from(["n_arc", "n_limb"]))
        lowest = 2 if field == "n_arc" else 1
        value = draw(st.one_of(
            st.integers(max_value=lowest - 1),
            st.floats(allow_nan=True, allow_infinity=True),          # 18.0 is not an int either
            st.sampled_from(["18", None, True, False])))
    return field, value


# ----------------------------------------------------------------------------- valid inputs

@SLOW
@given(batch=st.lists(valid_params(), min_size=1, max_size=8),
       dt=st.sampled_from([1e-3, 2e-3]), steps=st.integers(1, 5),
       integrator=st.sampled_from(params_module.INTEGRATORS),
       jacobian=st.sampled_from(params_module.JACOBIANS))
def test_valid_batches_simulate_with_valid_status_and_finite_results(batch, dt, steps,
                                                                      integrator, jacobian):
    solver = ts.SolverConfig(dt=dt, integrator=integrator, jacobian=jacobian)
    duration = steps * dt
    result = ts.simulate(batch, duration, solver=solver, record_interval_s=dt, record_shapes=True)
    summary = result.summary
    assert len(summary) == len(batch)
    assert list(summary["gait"]) == [p.gait for p in batch]  # input order, parameters echoed
    assert set(summary["status"]) <= {"ok", "newton_failed", "non_finite"}
    ok = (summary["status"] == "ok").to_numpy()
    for column in ("displacement_x_mm", "displacement_y_mm", "speed_mm_s", "heading_deg",
                   "newton_iterations_mean"):
        assert np.isfinite(summary.loc[ok, column]).all(), column
    # signed speed is defined where the gait has a forward direction
    has_forward = np.array([Gait.parse(p.gait).forward is not None for p in batch])
    assert np.isfinite(summary.loc[ok & has_forward, "signed_speed_mm_s"]).all()
    assert summary.loc[ok & ~has_forward, "signed_speed_mm_s"].isna().all()
    assert summary.loc[ok, "failure_time_s"].isna().all()
    assert (summary["newton_iterations_max"] <= solver.max_newton).all()
    # fixed steps reject nothing; a step is redone with substeps at most once (a failed
    # instance's last, failed step included)
    assert (summary["rejected_steps"] == 0).all()
    assert (summary["substep_retries"] <= summary["steps"] + ~ok).all()
    # a failed instance is reported with a failure time within the run, never with a speed
    failed = summary[~ok]
    assert ((failed["failure_time_s"] >= 0) & (failed["failure_time_s"] <= duration + 1e-12)).all()
    assert failed["speed_mm_s"].isna().all()
    # shapes and trajectory are finite for ok instances at every record (steps + 1 records)
    assert result.shapes.shape == (steps + 1, len(batch), result.topology.n_nodes, 2)
    assert np.isfinite(result.shapes[:, ok]).all()
    trajectory = result.trajectory
    assert len(trajectory) == (steps + 1) * len(batch)
    ok_rows = np.isin(trajectory["instance"], np.flatnonzero(ok))
    assert np.isfinite(trajectory.loc[ok_rows, ["x_mm", "y_mm"]].to_numpy()).all()


# ----------------------------------------------------------------------------- invalid inputs

@FAST
@given(invalid_star_field())
def test_invalid_star_params_raise_value_error_naming_the_field(case):
    field, value = case
    with pytest.raises(ValueError, match=field):
        ts.StarParams(**{field: value})


@FAST
@given(joint_radius=st.floats(LARGEST_JOINT_RADIUS, 0.05), data=st.data())
def test_inconsistent_geometry_names_the_field(joint_radius, data):
    # an arc of the rest curvature cannot span joints this far apart
    with pytest.raises(ValueError, match="joint_radius"):
        ts.StarParams(joint_radius=joint_radius, tip_radius=joint_radius + 0.03)
    # the tip must lie outside the joint
    tip = data.draw(st.floats(1e-4, 0.02))
    with pytest.raises(ValueError, match="tip_radius"):
        ts.StarParams(joint_radius=0.02, tip_radius=tip)
    # the period must contain the heating phase
    period = data.draw(st.floats(1e-6, CurvatureProfile().switch_time))
    with pytest.raises(ValueError, match="period"):
        ts.StarParams(period=period)


@st.composite
def invalid_solver_field(draw):
    field = draw(st.sampled_from(["dt", "newton_tol", "max_newton", "precision", "integrator",
                                  "jacobian", "max_substep_halvings"]))
    if field == "dt":
        value = draw(st.one_of(NOT_A_REAL, st.floats(max_value=0.0, allow_nan=False),
                               st.floats(min_value=1.0, exclude_min=True)))
    elif field == "newton_tol":
        # None is its default: the precision's own tolerance
        value = draw(st.one_of(NOT_A_REAL.filter(lambda v: v is not None),
                               st.floats(max_value=0.0, allow_nan=False)))
    elif field in ("max_newton", "max_substep_halvings"):
        lowest = 1 if field == "max_newton" else 0
        value = draw(st.one_of(st.integers(max_value=lowest - 1),
                               st.floats(allow_nan=True), st.sampled_from(["5", None, True])))
    else:
        choices = {"precision": params_module.PRECISIONS,
                   "integrator": params_module.INTEGRATORS,
                   "jacobian": params_module.JACOBIANS}[field]
        value = draw(st.one_of(st.text(max_size=6).filter(lambda s: s not in choices),
                               st.sampled_from([None, 64])))
    return field, value


@FAST
@given(invalid_solver_field())
def test_invalid_solver_config_raises_value_error_naming_the_field(case):
    field, value = case
    with pytest.raises(ValueError, match=field):
        ts.SolverConfig(**{field: value})


@FAST
@given(tol=st.floats(1e-300, 1e-7, exclude_max=True))
def test_f32_rejects_tolerances_it_cannot_resolve(tol):
    with pytest.raises(ValueError, match="newton_tol"):
        ts.SolverConfig(precision="f32", newton_tol=tol)


@st.composite
def invalid_simulate_call(draw):
    """(keyword arguments of simulate, the argument name its error must mention)."""
    base = dict(params=[ts.StarParams()], duration_s=0.002,
                solver=ts.SolverConfig(dt=1e-3))
    kind = draw(st.sampled_from(["duration", "record_interval_s", "empty", "topology", "arch",
                                 "params", "shapes"]))
    if kind == "duration":
        base["duration_s"] = draw(st.one_of(
            st.floats(max_value=0.0, allow_nan=False), st.sampled_from([math.nan, math.inf,
                                                                         "1", None])))
        return base, "duration_s"
    if kind == "record_interval_s":
        base["record_interval_s"] = draw(st.one_of(
            st.floats(max_value=-1e-9), st.sampled_from([math.nan, math.inf, "10", 0.0015])))
        return base, "record_interval_s"
    if kind == "empty":
        base["params"] = draw(st.sampled_from([[], ()]))
        return base, "empty"
    if kind == "topology":
        n_arc = draw(st.integers(2, 40).filter(lambda n: n != 18))
        n_limb = draw(st.integers(1, 12))
        other = ts.StarParams(n_arc=n_arc, n_limb=n_limb)
        position = draw(st.integers(0, 2))
        params = [ts.StarParams()] * 2
        params.insert(position, other)
        base["params"] = params
        return base, "n_arc"
    if kind == "arch":
        base["arch"] = draw(st.text(max_size=8).filter(
            lambda a: a not in ts.available_archs()))
        return base, "arch"
    if kind == "params":
        base["params"] = draw(st.sampled_from([ts.StarParams, [ts.StarParams(), "A1"],
                                               [ts.StarParams(), None], "A1"]))
        return base, "params"
    base["record_shapes"] = True   # shapes need a record stride
    return base, "record_shapes"


@FAST
@given(invalid_simulate_call())
def test_invalid_simulate_arguments_raise_value_error_naming_them(case):
    kwargs, name = case
    with pytest.raises(ValueError, match=name):
        ts.simulate(**kwargs)


SCALED_BY_LAMBDA = ("youngs_modulus", "actuator_density", "foam_density",
                    "cylinder_mass_per_height", "drag_perpendicular", "drag_parallel",
                    "cylinder_drag", "added_mass_coeff", "cylinder_added_mass_coeff")


OPTIONAL_FORCES = {"linear_drag": 1.0, "hub_linear_drag": 0.1, "wake_coupling": 1.0}
"""The optional terms' force coefficients (Pa·s/m, Pa·s, Pa·s), scaled by λ with the others;
jet_inflow, a ratio like α, by √λ (its force is ∝ its square)."""


@pytest.mark.parametrize("optional_terms", [False, True])
@pytest.mark.parametrize("alpha_power, same", [(0.5, True), (1.0, False)])
def test_every_mass_and_force_scaled_together_leave_the_motion_unchanged(alpha_power, same,
                                                                          optional_terms):
    """An exact invariance of the model: every mass (the densities, the hub's mass per height),
    every force coefficient (Young's modulus, the drags, the added masses) × λ and α × √λ (the
    jet force is ∝ α²) scale the residual by λ, so the path is the same: kinematic data cannot
    fix the absolute scale (docs/results.md, "What the data determine"). The two runs' Newton
    iterations see the same updates up to rounding, so the paths agree to far inside 1e-6 mm
    (10 × newton_tol; 8e-12 mm measured over a period; 2.5e-13 mm over these 0.3 s, the hub's
    added mass and the damping on); α × λ instead moves them by millimetres (1.3 mm), and a hub
    added mass not linear in its coefficient by 0.09 mm."""
    options = {**OPTIONAL_FORCES, "jet_inflow": 0.3} if optional_terms else {}
    # the hub's added mass and the rods' damping are 0 by default, which λ leaves 0: on, so
    # that their scaling is exercised (the damping's force is ∝ E·τ: τ, a time, is not scaled)
    base = ts.StarParams(gait="A1+A3", cylinder_added_mass_coeff=1.0, damping_time=1e-3,
                         **options)
    lam = 2.0
    scaled_names = SCALED_BY_LAMBDA + (tuple(OPTIONAL_FORCES) if optional_terms else ())
    changes = {name: getattr(base, name) * lam for name in scaled_names}
    if optional_terms:
        changes["jet_inflow"] = base.jet_inflow * lam ** alpha_power
    scaled = base.replace(alpha=base.alpha * lam ** alpha_power, **changes)
    result = ts.simulate([base, scaled], 0.3, record_interval_s=0.05)
    assert (result.summary.status == "ok").all()
    paths = [result.trajectory[result.trajectory.instance == i][["x_mm", "y_mm"]].to_numpy()
             for i in (0, 1)]
    difference = np.abs(paths[0] - paths[1]).max()
    assert (difference < 1e-6) if same else (difference > 1e-2), difference
