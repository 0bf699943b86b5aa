"""A force term is compiled into a batch's engine when any instance needs it: a batch of
instances each with one coefficient of a term on and another off (C∥ = 0 beside C⊥, the
cylinder's drag in one instance, the jet as its inflow alone, a rod's linear drag without the
hub's) uses every such term, and matches the NumPy reference. Found by a mutation audit of the
terms' host code (2026-12-07): switches asking for all of a term's coefficients, or for α
alone, lived through the suite."""

import numpy as np

import taichi_star as ts
from taichi_star.model import build_model
from taichi_star.physics.cylinder_drag import CylinderDrag
from taichi_star.physics.jet import Jet
from taichi_star.physics.linear_drag import LinearDrag
from taichi_star.physics.rod_drag import RodDrag
from taichi_star.physics.wake import Wake
from taichi_star.reference import ReferenceSimulator

COARSE = dict(n_arc=6, n_limb=2)

# Every instance of the batch lacks what some term's switch may wrongly require: C∥ = 0 (the
# rod drag is C⊥ alone), α = 0 (the jet is the inflow alone, on the hub direction and the hub
# application: no "variants" but the inflow), a rod linear drag without the hub's; and the
# cylinder's drag and the wake are on in one instance only.
SWITCH_BATCH = [
    ts.StarParams(gait="A1+A2", drag_parallel=0.0, alpha=0.0, jet_inflow=0.6, linear_drag=50.0,
                  wake_coupling=5.0, wake_time=0.05, **COARSE),
    ts.StarParams(gait="A1+A3", drag_parallel=0.0, alpha=0.0, cylinder_drag=0.0, **COARSE),
]


def test_a_term_is_compiled_in_when_any_of_its_coefficients_is_on():
    """terms_used of a batch that switches on one coefficient of a term and not the other."""
    used = dict(build_model(SWITCH_BATCH).terms_used)
    assert RodDrag in used and LinearDrag in used and CylinderDrag in used and Wake in used
    assert used[Jet] == ("variants",)


def test_the_engine_matches_the_reference_with_one_coefficient_of_each_term_on():
    """The same batch in the engine and the reference after 20 steps of 2 ms into the first
    pulse (the fired spaces open and draw in): a term compiled out by a switch that wanted all
    its coefficients on (C∥ and C⊥, the cylinder's drag in every instance, α with the inflow)
    moves the robot by 2.5e-4 of its motion and more (the inflow alone; measured)."""
    solver = ts.SolverConfig(newton_tol=1e-12, dt=2e-3)
    n_steps = 20
    result = ts.simulate(SWITCH_BATCH, n_steps * solver.dt, solver=solver,
                         record_interval_s=n_steps * solver.dt, record_shapes=True)
    assert (result.summary.status == "ok").all()
    engine = result.shapes[-1]
    for index, params in enumerate(SWITCH_BATCH):
        reference = ReferenceSimulator(params, solver).run(n_steps)
        error = np.abs(engine[index] - reference[-1]).max()
        motion = np.abs(reference[-1] - reference[0]).max()
        # both sides converge Newton to 1e-12 m; measured 3e-17 m against a motion of ~2e-3 m:
        # 1e-7 of the motion leaves room for another platform's rounding and fails a missing
        # force's 2.5e-4
        assert error <= 1e-7 * motion, (index, error, motion)
