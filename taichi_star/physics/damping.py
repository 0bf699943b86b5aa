"""Kelvin–Voigt material damping on every element of every strain term (`strain.StrainTerm`:
the stretching edges and the bending triplets).

A viscous force on the rate of each element's elastic strain s − s⁰ (ε for stretching,
δ = κ − κ⁰ for bending): f = −τ·k_s·ṡ·∇s with the element's own stiffness (k_s = E·r0·Δl̄ for
stretching, (E·r0³/12)·Δl for bending) and τ = `damping_time`; a mode of angular frequency ω gets the damping
ratio ζ = ωτ/2. The rate is the integrator's own: ṡ = γ·(s − s_k) + o, with γ its rate gain and
o its offset from the history (implicit Euler: (s − s_k)/h; BDF2: (3s − 4s_k + s_{k−1})/(2h)).
Since s_k and o are fixed during a step, f is the gradient of the pseudo-energy
½·τγ·k_s·(s − s*)², s* = s_k − o/γ: the same form as the elastic energy with stiffness τγ·k and a
moving target. Added to the element's elastic energy ½·k_s·(s − s⁰)² it gives one energy of the
same form, ½·k_s(1 + τγ)·(s − (s⁰ + τγ·s*)/(1 + τγ))² plus a constant, so the term reshapes the
strain elements (`Term.reshapes`) rather than assembling its own: each element is
evaluated and scattered once, and the Jacobian stays exact and symmetric. Without damping (τ = 0
everywhere) the term is compiled out.
"""

import numpy as np
import taichi as ti

from .base import Term
from .strain import StrainTerm


@ti.data_oriented
class MaterialDamping(Term):
    name = "damping"
    internal = True  # a pseudo-energy of the strain elements' rates
    # τ barely moves the robot (elasticities d ln v / d ln τ of 5e-5 to 3.5e-3 at 0.94 ms, every
    # optional term on, three cycles of the five Fig. 4c gaits, Newton to 1e-12 m): at ε = 1e-4
    # its derivative was 2.6e-4 and 4.3e-4 off for A1+A3 and A1+A3+A5 (implicit Euler) and
    # moved with ε; at 1e-3 and 1e-2 the derivatives agree with each other to 1.3e-5 (Euler)
    # and 4e-7 (BDF2), and at 1e-3 with differences of whole runs at 1e-3 within 2.6e-5 (Euler,
    # where those spread by up to 3.9e-5) and 1.2e-6 (BDF2). 1e-3 rather than 1e-2 because
    # `sensitivity_check` differences whole runs at the same step, and at 1e-2 the runs'
    # curvature in τ spreads those by up to 1e-3. The force is linear in τ
    sensitivity_steps = {"damping_time": 1e-3}

    @classmethod
    def reshapes(cls, other):
        return issubclass(other, StrainTerm)

    @staticmethod
    def coefficients(params, topologies, topology):
        return {"damping_time": np.array([p.damping_time for p in params])}

    @staticmethod
    def configuration(coefficients):
        return () if (coefficients["damping_time"] > 0).any() else None

    @staticmethod
    def reshaping(coefficients):
        # τ = 0 leaves an element's stiffness and target as they are (factors 1 + 0, offsets 0)
        return coefficients["damping_time"] > 0

    @classmethod
    def history(cls, topology, terms=()):
        # per element of each strain term: s_k − s⁰ (for the next step's BDF2 offset) and the
        # target s* − s⁰ of this step
        histories = {}
        for other in terms:
            if cls.reshapes(other):
                elements = (other.element_count(topology),)
                histories[f"{other.name}_previous_strain"] = elements
                histories[f"{other.name}_strain_target"] = elements
        return histories

    def strain_history(self, term):
        """(previous strain, strain target) fields of a reshaped term's elements."""
        return (getattr(self, f"{term.name}_previous_strain"),
                getattr(self, f"{term.name}_strain_target"))

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        """Record every element's strain at the step's start (with s⁰ at the start time) and
        the target of the pseudo-energy. Runs after the strain terms' begin_step (registry
        order), which sets their natural strains of this step."""
        for term in ti.static(self.reshaped_terms):
            previous, target = ti.static(self.strain_history(term))
            for e in range(term.n_elements):
                excess = term.strain(b, e) - term.natural_strain(b, e, 1)
                offset = self.assembly.rate_offset(excess, previous[b, e], h, ratio, use_history)
                target[b, e] = excess - offset / rate_gain
                previous[b, e] = excess

    @ti.func
    def reshape(self, b, term: ti.template(), element, stiffness, target, rate_gain):
        # ½k(s − s⁰)² + ½ck(s − s*)² with c = τγ is ½k(1 + c)(s − (s⁰ + c·s*)/(1 + c))² plus a
        # constant; the targets are kept as offsets from the elastic one
        viscosity = self.damping_time[b] * rate_gain
        offset = ti.static(self.strain_history(term)[1])[b, element]
        return stiffness * (1.0 + viscosity), target + viscosity * offset / (1.0 + viscosity)
