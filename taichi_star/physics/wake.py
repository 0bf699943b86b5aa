"""The water the robot sets moving (its wake), off unless `wake_coupling` is set.

The drag laws and the added mass of the other terms are instantaneous: the force at a moment
depends on the motion at that moment. A swimming body also sets a body of water moving with it
(the boundary layer it drags along, its wake), which keeps moving after a stroke and carries
the body on through the glide. The measured robot comes up to speed over its first five or six
cycles (A1+A2 from 1.5 to 3.8 mm/s per cycle); the model with instantaneous forces settles in
one or two, and a robot that is faster in the glide is also faster from the first cycle on.

We lump that water into one mass m_w per unit height with one velocity u (planar, uniform),
exchanging momentum with the hub through a linear coupling c_w: the hub feels
F = c_w·(u − v) (v its velocity) and the water −F, so m_w·u̇ = c_w·(v − u), i.e.
u̇ = (v − u)/τ_w with τ_w = m_w/c_w (`wake_time`). The robot and its water conserve their joint
momentum under their mutual force (tests/model/test_wake.py), so what the water takes during a
pulse it gives back during the glide, and a robot starting from rest has to bring m_w up to
speed too: a start-up over a time set by m_w, which the drag laws do not fix. c_w → 0 entrains
nothing; τ_w → 0 makes the water follow the hub (no force).

Discretisation: u advances by the nodes' integrator, implicitly within each step. With γ and o
the integrator's rate gain and offset (the rate of u over the step is γ·(u' − u_k) + o), the
step's end value u' solves γ·(u' − u_k) + o = (v' − u')/τ_w, so at a Newton iterate

    u' = (γ·u_k − o + v'/τ_w)/(γ + 1/τ_w),   F = c_w·(u' − v') = c_w·(γ·(u_k − v') − o)/(γ + 1/τ_w),

and ∂F/∂x_hub = −c_w·γ²/(γ + 1/τ_w)·I (∂v'/∂x = γ). The water is thereby solved with the
nodes, not lagged a step. u' is committed only when the engine accepts the step
(`accept_step`; a rejected adaptive step leaves u_k), and kept with the positions in the
engine's backup of a step redone in substeps (`copy_carried`). The NumPy reference solves the
same step with u as two more unknowns (`reference.ReferenceSimulator`), not eliminated.
"""

from typing import ClassVar

import numpy as np
import taichi as ti

from ..geometry import CENTRE
from .base import Term


@ti.data_oriented
class Wake(Term):
    name = "wake"
    carries_state: ClassVar[bool] = True

    @staticmethod
    def coefficients(params, topologies, topology):
        """wake_coupling (B,) c_w, Pa·s; wake_rate (B,) 1/τ_w, 1/s."""
        return {"wake_coupling": np.array([p.wake_coupling for p in params]),
                "wake_rate": np.array([1.0 / p.wake_time for p in params])}

    @staticmethod
    def configuration(coefficients):
        return () if (coefficients["wake_coupling"] > 0).any() else None

    @staticmethod
    def history(topology, terms=()):
        # u at the step's start and one step before (m/s), and the integrator's offset of u̇
        return {"water_velocity": (2,), "water_previous": (2,), "water_rate_offset": (2,)}

    def build(self, topology):
        self.centre_slot = self.assembly.slot(CENTRE, CENTRE)
        capacity = self.assembly.capacity
        self.backup_velocity = self.assembly.batch_field(float, (capacity, 2))
        self.backup_previous = self.assembly.batch_field(float, (capacity, 2))

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        for c in ti.static(range(2)):
            self.water_rate_offset[b, c] = self.assembly.rate_offset(
                self.water_velocity[b, c], self.water_previous[b, c], h, ratio, use_history)

    @ti.func
    def water_and_force(self, b, hub_velocity, rate_gain):
        """(u' (2,) m/s, F (2,) N/m on the hub) for the hub's velocity v' (2,) m/s."""
        start = ti.Vector([self.water_velocity[b, 0], self.water_velocity[b, 1]])
        offset = ti.Vector([self.water_rate_offset[b, 0], self.water_rate_offset[b, 1]])
        rate = self.wake_rate[b]
        denominator = rate_gain + rate
        water = (rate_gain * start - offset + rate * hub_velocity) / denominator
        force = self.wake_coupling[b] * (rate_gain * (start - hub_velocity) - offset) / denominator
        return water, force

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        hub_velocity = self.assembly.implicit_velocity(b, CENTRE, rate_gain)
        _, force = self.water_and_force(b, hub_velocity, rate_gain)
        self.assembly.add_residual(b, CENTRE, -force)
        stiffness = self.wake_coupling[b] * rate_gain * rate_gain / (rate_gain + self.wake_rate[b])
        self.assembly.add_block(b, self.centre_slot, stiffness * ti.Matrix.identity(float, 2),
                                jacobian)

    @ti.func
    def accept_step(self, b, rate_gain):
        water, _ = self.water_and_force(
            b, self.assembly.implicit_velocity(b, CENTRE, rate_gain), rate_gain)
        for c in ti.static(range(2)):
            self.water_previous[b, c] = self.water_velocity[b, c]
            self.water_velocity[b, c] = water[c]

    @ti.func
    def copy_carried(self, b, save):
        for c in ti.static(range(2)):
            if save:
                self.backup_velocity[b, c] = self.water_velocity[b, c]
                self.backup_previous[b, c] = self.water_previous[b, c]
            else:
                self.water_velocity[b, c] = self.backup_velocity[b, c]
                self.water_previous[b, c] = self.backup_previous[b, c]
