"""Kelvin–Voigt material damping on every stretching edge and bending triplet.

A viscous force on the rate of each element's elastic strain s (ε for stretching, δ = κ − κ⁰ for
bending): f = −τ·k_s·ṡ·∇s with the element's own stiffness (k_s = E·r0·Δl̄ for stretching,
(E·r0³/12)·Δl for bending) and τ = `damping_time`; a mode of angular frequency ω gets the damping
ratio ζ = ωτ/2. The rate is the integrator's own: ṡ = γ·(s − s_k) + o, with γ its rate gain and
o its offset from the history (implicit Euler: (s − s_k)/h; BDF2: (3s − 4s_k + s_{k−1})/(2h)).
Since s_k and o are fixed during a step, f is the gradient of the pseudo-energy
½·τγ·k_s·(s − s*)², s* = s_k − o/γ: the same form as the elastic energy with stiffness τγ·k and a
moving target. Added to the element's elastic energy ½·k_s·(s − s⁰)² it gives one energy of the
same form, ½·k_s(1 + τγ)·(s − (s⁰ + τγ·s*)/(1 + τγ))² plus a constant, so the term reshapes the
stretching and bending elements (`Term.reshapes`) rather than assembling its own: each element is
evaluated and scattered once, and the Jacobian stays exact and symmetric. Without damping (τ = 0
everywhere) the term is compiled out.
"""

import numpy as np
import taichi as ti

from .base import Term
from .bending import turning_tangent


@ti.data_oriented
class MaterialDamping(Term):
    name = "damping"
    reshapes = ("stretching", "bending")

    @staticmethod
    def coefficients(params, topologies, topology):
        return {"damping_time": np.array([p.damping_time for p in params])}

    @staticmethod
    def configuration(coefficients):
        return () if (coefficients["damping_time"] > 0).any() else None

    @staticmethod
    def history(topology):
        # s_k of every element (for the next step's BDF2 offset) and the target s* of this step
        return {"previous_strain": (topology.n_edges,), "strain_target": (topology.n_edges,),
                "previous_bend": (topology.n_triplets,), "bend_target": (topology.n_triplets,)}

    def build(self, topology):
        self.stretching = self.engine.term("stretching")
        self.bending = self.engine.term("bending")

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        """Record every element's strain at the step's start (with κ⁰ at the start time) and
        the target of the pseudo-energy. Runs after the bending term's begin_step, which sets
        the natural curvatures of this step."""
        positions = ti.static(self.engine.state.positions)
        for e in range(self.stretching.n_edges):
            i, j = self.stretching.edges[e, 0], self.stretching.edges[e, 1]
            strain = (positions[b, j] - positions[b, i]).norm() / self.stretching.rest_length[b, e] - 1.0
            offset = self.engine.integrator.rate_offset(strain, self.previous_strain[b, e], h, ratio, use_history)
            self.strain_target[b, e] = strain - offset / rate_gain
            self.previous_strain[b, e] = strain
        for t in range(self.bending.n_triplets):
            i, j, k, edge1, edge2 = self.bending.edges_of(b, t)
            curvature = 2.0 * turning_tangent(edge1, edge2) / self.bending.voronoi_length[b, t]
            excess = curvature - self.bending.natural_curvature(b, t, 1)
            offset = self.engine.integrator.rate_offset(excess, self.previous_bend[b, t], h, ratio, use_history)
            self.bend_target[b, t] = excess - offset / rate_gain
            self.previous_bend[b, t] = excess

    @ti.func
    def reshape(self, b, term: ti.template(), element, stiffness, target, rate_gain):
        # ½k(s − s⁰)² + ½ck(s − s*)² with c = τγ is ½k(1 + c)(s − (s⁰ + c·s*)/(1 + c))² plus a
        # constant; the targets are kept as offsets from the elastic one
        viscosity = self.damping_time[b] * rate_gain
        offset = 0.0
        if ti.static(term.name == "stretching"):
            offset = self.strain_target[b, element]
        else:
            offset = self.bend_target[b, element]
        return stiffness * (1.0 + viscosity), target + viscosity * offset / (1.0 + viscosity)
