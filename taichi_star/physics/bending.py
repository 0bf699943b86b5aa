"""Bending at every interior node of a limb or an arc and at the joints, driven by the actuation.

E_b = ½·(E·r0³/12)·(κ − κ⁰)²·Δl with the discrete curvature κ = 2·tan(φ/2)/Δl of the turning
angle φ between the triplet's two edges and Δl its rest Voronoi length. κ⁰ is the rest curvature
except on fired actuators: their interior triplets follow ±K̄(τ) (the actuation profile at the
time τ since the actuator last fired) and, with `actuation_ends="shared"`, the joint triplets clamping
their ends turn by the curvature change of the arc's end half-edge. Joint triplets use E_limb
("limb") or a half arc edge in series with a half limb edge ("series").

Per-actuator heterogeneity (`actuator_gains`, `actuator_delays`): actuator A_k follows
K̄(0) + g_k·(K̄(max(τ − d_k, 0)) − K̄(0)). The gain and the delay are applied only where they
differ from 1 and 0, so that the default actuators compute exactly the arithmetic they computed
without them (K̄(0) + 1·(K̄ − K̄(0)) is not always K̄ to the last bit).

The stroke's warming (`stroke_warming` w, `cooling_time` τ_c): a firing's gain is g_k·(1 + w·θ),
θ the heat the actuator keeps from its earlier firings: 0 at its first firing, and at each later
one θ' = (θ + 1)·exp(−Δt/τ_c), Δt the time since the firing before (each firing adds one unit,
which decays between firings). The term keeps θ per actuator as history, updated at the start
of a step where the actuator's firing time has moved (`begin_step`), with the θ of the firing
before for the times before the new one; a firing that a later one replaces before any step has
begun from it adds nothing. Applied only where w differs from 0.
"""

import numpy as np
import taichi as ti

from ..actuation import SWITCH_SNAP
from ..gait import N_ACTUATORS, Gait
from ..geometry import ARC_BEND, JOINT_BEND
from .strain import StrainTerm

NOT_FIRED = -1e30
"""Marks an actuator that has not fired (far below any K̄: with a gain ≤ 5 the profile's K̄
stays above −500 1/m)."""


@ti.func
def turning_tangent(edge1, edge2):
    """tan(φ/2) of the turning angle φ from edge1 to edge2 (signed, counter-clockwise > 0)."""
    cross = edge1[0] * edge2[1] - edge1[1] * edge2[0]
    return cross / (edge1.norm() * edge2.norm() + edge1.dot(edge2))


@ti.func
def bend_energy(edge1, edge2, voronoi_length, natural_curvature, bending_stiffness):
    """E_b = ½·B·(κ − κ⁰)²·Δl, B = E·r0³/12 (N·m²), edges (2,) m. Returns J/m."""
    curvature = 2.0 * turning_tangent(edge1, edge2) / voronoi_length
    excess = curvature - natural_curvature
    return 0.5 * bending_stiffness * excess * excess * voronoi_length


@ti.func
def angle_gradient_hessian(edge):
    """Gradient (2,) and Hessian (2, 2) of the edge's polar angle θ = atan2(e_y, e_x)."""
    squared = edge.dot(edge)
    gradient = ti.Vector([-edge[1], edge[0]]) / squared
    xy = 2.0 * edge[0] * edge[1]
    diff = edge[1] * edge[1] - edge[0] * edge[0]
    return gradient, ti.Matrix([[xy, diff], [diff, -xy]]) / (squared * squared)


@ti.func
def bend_gradient_hessian(edge1, edge2, voronoi_length, natural_curvature, bending_stiffness):
    """Derivatives of `bend_energy` with respect to (e1, e2): gradients g1, g2 (2,) and Hessian
    blocks H11, H12, H22 (2, 2) (H21 = H12ᵀ), by the chain rule through φ = θ(e2) − θ(e1):
    dκ/dφ = (1 + tan²(φ/2))/Δl, d²κ/dφ² = tan(φ/2)(1 + tan²(φ/2))/Δl."""
    half_tangent = turning_tangent(edge1, edge2)
    curvature = 2.0 * half_tangent / voronoi_length
    dcurv = (1.0 + half_tangent * half_tangent) / voronoi_length
    d2curv = half_tangent * dcurv
    scale = bending_stiffness * voronoi_length
    excess = curvature - natural_curvature
    energy_phi = scale * excess * dcurv
    energy_phi_phi = scale * (dcurv * dcurv + excess * d2curv)
    grad1, hess1 = angle_gradient_hessian(edge1)
    grad2, hess2 = angle_gradient_hessian(edge2)
    h11 = energy_phi_phi * grad1.outer_product(grad1) - energy_phi * hess1
    h22 = energy_phi_phi * grad2.outer_product(grad2) + energy_phi * hess2
    h12 = -energy_phi_phi * grad1.outer_product(grad2)
    return -energy_phi * grad1, energy_phi * grad2, h11, h12, h22


def triplet_modulus(params, topologies, topology) -> np.ndarray:
    """(B, T) Young's modulus of every bending triplet, Pa: E on arcs, E_limb on limbs, and on
    joints E_limb ("limb") or Δl_j / (½Δl_a/E + ½Δl_l/E_limb) ("series"; Δl_a, Δl_l the rest
    lengths of the joint triplet's arc and limb edges in the instance's own rest shape, from
    `topologies`, Δl_j their mean)."""
    youngs = np.array([p.youngs_modulus for p in params])[:, None]
    limb = np.array([p.limb_modulus for p in params])[:, None]
    modulus = np.where(topology.triplet_kind == ARC_BEND, youngs, limb)
    series = np.array([p.joint_stiffness == "series" for p in params])
    if series.any():
        joint = topology.triplet_kind == JOINT_BEND
        nodes = topologies.stack("rest_positions")[:, topology.triplets[joint]]  # (B, J, 3, 2)
        arc_length = np.linalg.norm(nodes[:, :, 1] - nodes[:, :, 0], axis=-1)
        limb_length = np.linalg.norm(nodes[:, :, 2] - nodes[:, :, 1], axis=-1)
        combined = (0.5 * (arc_length + limb_length)
                    / (0.5 * arc_length / youngs + 0.5 * limb_length / limb))
        modulus[:, joint] = np.where(series[:, None], combined, modulus[:, joint])
    return modulus


@ti.data_oriented
class Bending(StrainTerm):
    """Strain elements: the triplets, s = κ, k = E·r0³/12 (its energy ½·k·(κ − κ⁰)²·Δl)."""

    name = "bending"
    linear_coefficients = ("bend_stiffness",)
    fired_columns = ("actuator_gain", "actuator_delay")  # read in actuator_curvature alone
    # the natural curvature is the rest one plus gain·(1 + warming·heat) times the profile's
    # change, and the bending force linear in it
    linear_fields = ("actuator_gains", "stroke_warming")

    @staticmethod
    def coefficients(params, topologies, topology):
        thickness = np.array([p.thickness for p in params])[:, None]
        shared = np.array([p.actuation_ends == "shared" for p in params], dtype=np.float64)
        profiles = [p.actuator_profile for p in params]
        return {
            "voronoi_length": topologies.stack("voronoi_length"),
            "rest_curvature": topologies.stack("rest_curvature"),
            "end_turning_length": topologies.stack("end_turning_length") * shared[:, None],
            "bend_stiffness": triplet_modulus(params, topologies, topology) * thickness ** 3 / 12.0,
            "profile": np.stack([profile.as_array() for profile in profiles]),
            "profile_rest": np.array([profile.rest_curvature for profile in profiles]),
            "closure_rate": np.array([
                p.actuator_profile.closure_gap(p.period) / p.period
                if p.profile_closure == "ramp" else 0.0 for p in params]),
            "period": np.array([p.period for p in params]),
            "gait_mask": np.stack([Gait.parse(p.gait).mask for p in params]),
            "actuator_gain": np.array([p.actuator_gains for p in params]),
            "actuator_delay": np.array([p.actuator_delays for p in params]),
            "stroke_warming": np.array([p.stroke_warming for p in params]),
            "cooling_rate": np.array([1.0 / p.cooling_time for p in params]),
            "from_rest": np.array([p.actuation_origin == "rest" for p in params],
                                  dtype=np.float64),
        }
    """gait_mask (B, 8): the actuators an instance fires (its gait, or all eight for a
    commanded batch: `commanded`); the firing itself is in the batch state (fire times).
    actuator_gain (B, 8) (-) and actuator_delay (B, 8) (s): each actuator's gain on its
    curvature change and the delay of its profile after a firing. stroke_warming (B,) (-)
    and cooling_rate (B,) (1/s, 1/τ_c): the warming of the stroke by the heat kept from earlier
    firings. from_rest (B,): 1 where a fired triplet's κ⁰ is its rest κ⁰ plus the profile's
    change (`actuation_origin` "rest"), 0 where it is the profile's ±K̄ itself."""

    @staticmethod
    def commanded(coefficients):
        # any actuator may be commanded to fire
        return {**coefficients, "gait_mask": np.ones_like(coefficients["gait_mask"])}

    @staticmethod
    def configuration(coefficients):
        # only the actuation as a whole is compiled out: the shared ends and the ramp closure
        # are per-instance branches that cost nothing measurable, and each static switch would
        # multiply the engines a batch of mixed options compiles
        return (bool(coefficients["gait_mask"].any()),)

    @staticmethod
    def coupled_pairs(topology):
        pairs = []
        for i, j, k in topology.triplets:
            pairs += [(i, j), (j, k), (i, k)]
        return pairs

    @staticmethod
    def element_count(topology):
        return topology.n_triplets

    @staticmethod
    def history(topology, terms=()):
        # K̄ of each actuator at the start and the end of the current step; the heat θ each
        # actuator keeps, of its current firing and of the one before, and the firing time and
        # count (0 or 1: whether one has been counted) the current θ belongs to
        return {"start_curvature": (N_ACTUATORS,), "end_curvature": (N_ACTUATORS,),
                "fire_heat": (N_ACTUATORS,), "previous_fire_heat": (N_ACTUATORS,),
                "heat_fire_time": (N_ACTUATORS,), "heat_counted": (N_ACTUATORS,)}

    def build(self, topology):
        (self.actuated,) = self.configuration_switches
        self.n_elements = topology.n_triplets
        self.triplets = self.assembly.index(topology.triplets)
        self.triplet_slot = self.assembly.triplet_slots(topology.triplets)
        self.triplet_actuator = self.assembly.index(topology.triplet_actuator)
        self.joint_actuator = self.assembly.index(topology.joint_actuator)

    @ti.func
    def profile_curvature(self, b, tau):
        """K̄ (1/m) of instance b's actuators at τ (s) since firing: Eq. 5, and with the "ramp"
        closure the gap K̄(0) − K̄(T) spread over the period, back at K̄(0) from τ = T on."""
        if self.closure_rate[b] != 0.0:
            tau = ti.min(tau, self.period[b])
        c1, c2, c3, c4 = self.profile[b, 0], self.profile[b, 1], self.profile[b, 2], self.profile[b, 3]
        if tau >= self.profile[b, 8]:
            c1, c2, c3, c4 = self.profile[b, 4], self.profile[b, 5], self.profile[b, 6], self.profile[b, 7]
        value = c1 / (1.0 + ti.exp(-c2 * (tau - c3))) + c4
        if self.closure_rate[b] != 0.0:
            value += self.closure_rate[b] * tau
        return value

    @ti.func
    def profile_rate(self, b, tau):
        """dK̄/dτ (1/(m·s)) of `profile_curvature` at τ (s), on the same branch."""
        rate = 0.0
        if self.closure_rate[b] == 0.0 or tau < self.period[b]:
            c1, c2, c3 = self.profile[b, 0], self.profile[b, 1], self.profile[b, 2]
            if tau >= self.profile[b, 8]:
                c1, c2, c3 = self.profile[b, 4], self.profile[b, 5], self.profile[b, 6]
            decay = ti.exp(-c2 * (tau - c3))
            rate = c1 * c2 * decay / ((1.0 + decay) * (1.0 + decay)) + self.closure_rate[b]
        return rate

    @ti.func
    def since_firing(self, b, m, since, time):
        """τ (s) of actuator m of instance b's profile, `since` s after its firing at `time`
        (s): its delay later, and 0 until then; within `actuation.SWITCH_SNAP` of the time of
        the profile's switch, the switch (a step that ends on it reads the cooling branch,
        whichever side the subtraction rounded to). Returns (τ, dτ/d(delay): −1, or 0 while it
        waits: also at a delay of 0 on the firing itself, where a longer delay leaves τ at 0;
        it was −1 there, so that every step ending on a firing gave a zero delay the heating
        slope's derivative, 4–35 % off the differences by a period's end: an audit, 2026-12)."""
        delay = self.actuator_delay[b, m]
        tau = since
        slope = -1.0
        if since - delay <= 0.0:
            slope = 0.0
        if delay != 0.0:
            tau = ti.max(since - delay, 0.0)
        switch = self.profile[b, 8]
        if ti.abs(tau - switch) <= SWITCH_SNAP * ti.max(ti.abs(time), 1.0):
            tau = switch
        return tau, slope

    @ti.func
    def actuator_curvature(self, b, m, time):
        """K̄ (1/m) of actuator m of instance b at `time` (s) by the firing that applies then,
        with the actuator's delay and gain, or NOT_FIRED when it has never fired by then. A
        replica (`Assembly.primal_instance`) takes the profile's first-order expansion in its
        delay about its instance's: the profile is steep (a heating time of ~16 ms) and jumps
        at its switch, which a replica pair at ±ε would straddle for the steps that end within
        ε of it."""
        fired = self.assembly.fire_time[b, m]
        heat = self.fire_heat[b, m]
        if time < fired:
            fired = self.assembly.previous_fire_time[b, m]
            heat = self.previous_fire_heat[b, m]
        value = NOT_FIRED
        if fired >= 0.0:
            since = time - fired
            primal = self.assembly.primal_instance(b)
            if primal != b:
                tau, slope = self.since_firing(primal, m, since, time)
                value = self.profile_curvature(b, tau) + self.profile_rate(b, tau) * slope * (
                    self.actuator_delay[b, m] - self.actuator_delay[primal, m])
            else:
                tau, _ = self.since_firing(b, m, since, time)
                value = self.profile_curvature(b, tau)
            gain = self.actuator_gain[b, m]
            if self.stroke_warming[b] != 0.0:
                gain *= 1.0 + self.stroke_warming[b] * heat
            if gain != 1.0:
                value = self.profile_rest[b] + gain * (value - self.profile_rest[b])
        return value

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        if ti.static(self.actuated):
            for m in range(N_ACTUATORS):
                self.count_firing(b, m)
                self.start_curvature[b, m] = self.actuator_curvature(b, m, start_time)
                self.end_curvature[b, m] = self.actuator_curvature(b, m, end_time)

    @ti.func
    def count_firing(self, b, m):
        """Count actuator m's current firing into instance b's heat θ if it has not been: θ of
        the firing before becomes `previous_fire_heat`, and the new θ is 0 for a first firing,
        else (θ + 1)·exp(−Δt/τ_c) with Δt the time since the firing last counted. Counting a
        firing again changes nothing, so a step redone from its start finds θ as it was."""
        fired = self.assembly.fire_time[b, m]
        if fired >= 0.0 and (self.heat_counted[b, m] == 0.0 or fired != self.heat_fire_time[b, m]):
            heat = 0.0
            if self.heat_counted[b, m] != 0.0:
                heat = (self.fire_heat[b, m] + 1.0) * ti.exp(
                    -(fired - self.heat_fire_time[b, m]) * self.cooling_rate[b])
            self.previous_fire_heat[b, m] = self.fire_heat[b, m]
            self.fire_heat[b, m] = heat
            self.heat_fire_time[b, m] = fired
            self.heat_counted[b, m] = 1.0

    @ti.func
    def natural_curvature(self, b, t, at_start):
        """κ⁰ (1/m) of triplet t of instance b at the start (at_start = 1) or the end of the
        current step."""
        natural = self.rest_curvature[b, t]
        if ti.static(self.actuated):
            actuator = self.triplet_actuator[t]
            if actuator >= 0:
                target = self.target_curvature(b, actuator, at_start)
                if target != NOT_FIRED:
                    if self.from_rest[b] != 0.0:
                        # the rest arc's own discrete curvature, moved by the profile's change
                        change = target - self.profile_rest[b]
                        natural += change if natural >= 0.0 else -change
                    else:
                        natural = target if natural >= 0.0 else -target
            clamped = self.joint_actuator[t]
            if clamped >= 0 and self.end_turning_length[b, t] != 0.0:
                target = self.target_curvature(b, clamped, at_start)
                if target != NOT_FIRED:
                    # turn the joint's natural angle φ⁰ = 2 atan(κ⁰Δl/2) by the arc's half-edge
                    voronoi = self.voronoi_length[b, t]
                    angle = 2.0 * ti.atan2(natural * voronoi, 2.0) + self.end_turning_length[b, t] * (
                        target - self.profile_rest[b])
                    natural = 2.0 * ti.tan(0.5 * angle) / voronoi
        return natural

    @ti.func
    def target_curvature(self, b, actuator, at_start):
        value = self.end_curvature[b, actuator]
        if at_start:
            value = self.start_curvature[b, actuator]
        return value

    @ti.func
    def edges_of(self, b, t):
        """(i, j, k, e1, e2) of triplet t at instance b's current positions."""
        positions = ti.static(self.assembly.positions)
        i, j, k = self.triplets[t, 0], self.triplets[t, 1], self.triplets[t, 2]
        return i, j, k, positions[b, j] - positions[b, i], positions[b, k] - positions[b, j]

    @ti.func
    def stiffness(self, b, t):
        return self.bend_stiffness[b, t]

    @ti.func
    def natural_strain(self, b, t, at_start):
        return self.natural_curvature(b, t, at_start)

    @ti.func
    def strain(self, b, t):
        _, _, _, edge1, edge2 = self.edges_of(b, t)
        return 2.0 * turning_tangent(edge1, edge2) / self.voronoi_length[b, t]

    @ti.func
    def add_element(self, b, t, stiffness, natural, jacobian):
        i, j, k, edge1, edge2 = self.edges_of(b, t)
        g1, g2, h11, h12, h22 = bend_gradient_hessian(
            edge1, edge2, self.voronoi_length[b, t], natural, stiffness)
        self.assembly.scatter_triplet(b, self.triplet_slot, t, i, j, k, g1, g2, h11, h12, h22,
                                      jacobian)
