"""Time integrators: each supplies only its inertia term and its discrete rates.

A step from q_k to q (the unknown) solves scale·M·((q − q_k) − d) + ∇E(q) − F(q) = 0, where the
integrator gives the inertia `scale` and offset d, and every rate the forces need (a node's
velocity, a jet space's Ṡ, an element's strain rate) is `gain`·(value − value_k) + offset with the
integrator's gain and offset. Nothing outside this module knows the formulas.

- `ImplicitEuler` (the paper's Eq. 4): scale 1/h², d = h·v_k, gain 1/h, rate offset 0.
- `BDF2`: scale 9/(4h²), d = (q_k − q_{k−1})/3 + (2h/9)(4v_k − v_{k−1}), gain 3/(2h), rate offset
  −(value_k − value_{k−1})/(2h); without a valid history (the first step, after a retry) it is
  implicit Euler.
Small offsets rather than absolute targets keep the digits of the motion in f32.
"""

import taichi as ti


@ti.data_oriented
class ImplicitEuler:
    name = "euler"
    order = 1

    @ti.func
    def weights(self, h, use_history):
        """(inertia scale 1/s², rate gain 1/s) of a step of size h (s)."""
        return 1.0 / (h * h), 1.0 / h

    @ti.func
    def rate_offset(self, value, previous, h, use_history):
        """Offset of the discrete rate of a quantity whose value at the step's start is `value`
        and one step earlier `previous` (scalar or vector)."""
        return value * 0.0

    @ti.func
    def inertia_offset(self, position, previous, velocity, previous_velocity, h, use_history):
        """d of the inertia term, m, from q_k, q_{k−1}, v_k, v_{k−1}."""
        return h * velocity


@ti.data_oriented
class BDF2:
    name = "bdf2"
    order = 2

    @ti.func
    def weights(self, h, use_history):
        scale, gain = 1.0 / (h * h), 1.0 / h
        if use_history:
            scale, gain = 9.0 / (4.0 * h * h), 1.5 / h
        return scale, gain

    @ti.func
    def rate_offset(self, value, previous, h, use_history):
        offset = value * 0.0
        if use_history:
            offset = -(value - previous) / (2.0 * h)
        return offset

    @ti.func
    def inertia_offset(self, position, previous, velocity, previous_velocity, h, use_history):
        offset = h * velocity
        if use_history:
            offset = (position - previous) / 3.0 + (2.0 * h / 9.0) * (4.0 * velocity - previous_velocity)
        return offset


INTEGRATORS = {integrator.name: integrator for integrator in (ImplicitEuler, BDF2)}
"""Integrator classes by their SolverConfig name."""
