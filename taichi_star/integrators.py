"""Time integrators: each supplies only its inertia term and its discrete rates.

A step from q_k to q (the unknown) solves scale·M·((q − q_k) − d) + ∇E(q) − F(q) = 0, where the
integrator gives the inertia `scale` and offset d, and every rate the forces need (a node's
velocity, a jet space's Ṡ, an element's strain rate) is `gain`·(value − value_k) + offset with the
integrator's gain and offset. Nothing outside this module knows the formulas.

- `ImplicitEuler` (the paper's Eq. 4): scale 1/h², d = h·v_k, gain 1/h, rate offset 0.
- `BDF2`: scale 9/(4h²), d = (q_k − q_{k−1})/3 + (2h/9)(4v_k − v_{k−1}), gain 3/(2h), rate offset
  −(value_k − value_{k−1})/(2h); without a valid history (the first step, after a retry) it is
  implicit Euler. With a step ratio ω = h/h_prev ≠ 1 (adaptive steps) it is the variable-step
  BDF2: gain γ = (1 + 2ω)/((1 + ω)h), rate offset −c·(value_k − value_{k−1}) with
  c = ω²/((1 + ω)h), scale γ² and d = (v_k + c(q_k − q_{k−1}))/γ + c(v_k − v_{k−1})/γ².
Small offsets rather than absolute targets keep the digits of the motion in f32.

Both share Newton's start (`predictor`) and the local error estimate of adaptive stepping
(`local_error`), which are the implicit Euler step's.
"""

import taichi as ti


@ti.data_oriented
class Integrator:
    """What every integrator has: Newton's start for a step and the local error estimate."""

    @ti.func
    def predictor(self, position, previous, velocity, previous_velocity, h, back, use_history,
                  extrapolate):
        """Newton's start for a node, m, from q_k (`position`), q_{k−1}, v_k, v_{k−1}: q_k + h·v_k
        without history, with it q_k + h·(2v_k − v_{k−1}) (fixed steps) or, with `extrapolate`
        (adaptive steps; `back`: the previous step's size, s), the parabola below."""
        predictor = position + h * velocity
        if use_history and not extrapolate:
            # + h²·(v_k − v_{k−1})/h: the acceleration of the last step carried on, a
            # second-order start that most coast steps accept after one update
            predictor += h * (velocity - previous_velocity)
        if extrapolate:
            # the parabola through q_{k−1} and q_k with slope v_k: a second-order start for
            # Newton, worth an iteration on the long steps of adaptive stepping
            curve = (previous - position + back * velocity) / (back * back)
            predictor += h * h * curve
        return predictor

    @ti.func
    def local_error(self, position, previous, previous_velocity, h):
        """A node's local error estimate of an implicit Euler step of size h, m:
        ½·max|q − q_k − h·v_k| over its two coordinates (the step's leading term h²·q''/2),
        from the step's end q and start q_k, v_k. For both integrators: BDF2's own error is
        smaller."""
        drift = position - previous - h * previous_velocity
        return ti.max(0.5 * ti.abs(drift[0]), 0.5 * ti.abs(drift[1]))


@ti.data_oriented
class ImplicitEuler(Integrator):
    name = "euler"
    order = 1

    @ti.func
    def weights(self, h, ratio, use_history):
        """(inertia scale 1/s², rate gain 1/s) of a step of size h (s), ratio = h / (the
        previous step's size)."""
        return 1.0 / (h * h), 1.0 / h

    @ti.func
    def rate_offset(self, value, previous, h, ratio, use_history):
        """Offset of the discrete rate of a quantity whose value at the step's start is `value`
        and one step earlier `previous` (scalar or vector)."""
        return value * 0.0

    @ti.func
    def inertia_offset(self, position, previous, velocity, previous_velocity, h, ratio, use_history):
        """d of the inertia term, m, from q_k, q_{k−1}, v_k, v_{k−1}."""
        return h * velocity


@ti.data_oriented
class BDF2(Integrator):
    name = "bdf2"
    order = 2

    # the constant-step formulas are kept apart from the variable-step ones (ω = 1 gives the same
    # values, not the same rounding): fixed-step results stay bitwise reproducible

    @ti.func
    def weights(self, h, ratio, use_history):
        scale, gain = 1.0 / (h * h), 1.0 / h
        if use_history:
            if ratio == 1.0:
                scale, gain = 9.0 / (4.0 * h * h), 1.5 / h
            else:
                gain = (1.0 + 2.0 * ratio) / ((1.0 + ratio) * h)
                scale = gain * gain
        return scale, gain

    @ti.func
    def rate_offset(self, value, previous, h, ratio, use_history):
        offset = value * 0.0
        if use_history:
            if ratio == 1.0:
                offset = -(value - previous) / (2.0 * h)
            else:
                offset = -(ratio * ratio / ((1.0 + ratio) * h)) * (value - previous)
        return offset

    @ti.func
    def inertia_offset(self, position, previous, velocity, previous_velocity, h, ratio, use_history):
        offset = h * velocity
        if use_history:
            if ratio == 1.0:
                offset = (position - previous) / 3.0 + (2.0 * h / 9.0) * (4.0 * velocity - previous_velocity)
            else:
                gain = (1.0 + 2.0 * ratio) / ((1.0 + ratio) * h)
                c = ratio * ratio / ((1.0 + ratio) * h)
                offset = (velocity + c * (position - previous)) / gain \
                    + c * (velocity - previous_velocity) / (gain * gain)
        return offset


INTEGRATORS = {integrator.name: integrator for integrator in (ImplicitEuler, BDF2)}
"""Integrator classes by their SolverConfig name."""
