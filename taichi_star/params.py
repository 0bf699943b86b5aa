"""Parameters: frozen, validated dataclasses (SI units; per unit out-of-plane height H = 1 m).

`StarParams` describes one robot instance (geometry, material, fluid, actuation); a batch is a
sequence of them and every field except the topology (`n_arc`, `n_limb`) may differ per instance.
`SolverConfig` is shared by the whole batch. Defaults are the paper's values (design §2).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields

from .actuation import PAPER_PROFILE, parse_gait

JET_MODES = ("contract", "always")
PRECISIONS = ("f64", "f32")
INTEGRATORS = ("euler", "bdf2")
JACOBIANS = ("newton", "chord")
ACTUATION_ENDS = ("clamped", "shared")
CONVERGED_DISCRETISATION = {"n_arc": 320, "n_limb": 6, "actuation_ends": "clamped"}
"""The converged preset (design §2.7), from `python -m studies convergence`: the five paper
gaits' one-cycle speeds converge at first order in 1/n_arc (observed orders 1.04-1.24 with
clamped ends), 8-19 % low at the paper's n_arc = 18 and 0.7-1.7 % at 144 against the
extrapolated limit; n_arc = 320 (N = 2609 nodes) measured 0.25-0.74 % off. The "shared" ends halve the
error of A1+A2 but enlarge it for the other paper gaits, so the preset keeps clamped ends."""


def _check_finite(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a real number, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")


def _check_positive(name, value):
    _check_finite(name, value)
    if value <= 0:
        raise ValueError(f"{name} must be > 0, got {value!r}")


def _check_non_negative(name, value):
    _check_finite(name, value)
    if value < 0:
        raise ValueError(f"{name} must be >= 0, got {value!r}")


def _check_int_at_least(name, value, lowest):
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValueError(f"{name} must be an integer >= {lowest}, got {value!r}")
    if value < lowest:
        raise ValueError(f"{name} must be an integer >= {lowest}, got {value!r}")


def _check_choice(name, value, choices):
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")


@dataclass(frozen=True)
class StarParams:
    """One star robot instance. Lengths in m, moduli in Pa, densities in kg/m³, times in s."""

    gait: str = "A1"
    """Actuators fired together each cycle: "A1".."A8" joined by "+" (no repeats), or "none"."""
    alpha: float = 0.8
    """Jet ratio α (-), the fraction of the squeezed fluid jetted in plane (Eq. 2); >= 0."""
    added_mass_coeff: float = 1.0
    """Added-mass coefficient C_a (-) of the rod nodes (Eq. 3); >= 0."""
    youngs_modulus: float = 5e6
    """E of the actuator arcs, Pa; > 0."""
    limb_stiffness_ratio: float = 100.0
    """E_limb / E (-) for limbs, spokes and joint bending; > 0."""
    drag_parallel: float = 0.01
    """Axial rod drag coefficient C∥ (-) (Eq. 1); >= 0."""
    drag_perpendicular: float = 1.0
    """Normal rod drag coefficient C⊥ (-) (Eq. 1); >= 0."""
    cylinder_drag: float = 10.0
    """Drag coefficient C_c (-) of the central cylinder; >= 0."""
    period: float = 3.15
    """Actuation period T, s (150 ms heating pulse + 3 s rest); must exceed the 0.163 s heating."""
    jet_mode: str = "contract"
    """"contract": jet only while the inter-limb space shrinks [recon]; "always": Eq. 2 literally."""
    thickness: float = 3.4e-3
    """Rod thickness r0, m; > 0."""
    actuator_density: float = 2700.0
    """Effective density of the actuator arcs, kg/m³; > 0."""
    foam_density: float = 700.0
    """Effective density of the foam limbs, kg/m³; > 0."""
    fluid_density: float = 1000.0
    """Water density ρ_f, kg/m³; > 0."""
    cylinder_mass_per_height: float = 0.98
    """Mass of the central cylinder per unit height, kg/m (49 g / 50 mm); > 0."""
    cylinder_diameter: float = 0.03
    """D_c = 2 R_c, m; > 0."""
    cylinder_added_mass_coeff: float = 0.0
    """Added-mass coefficient of the cylinder (-), mass ρ_f·C·π D_c²/4 [recon; paper: none]; >= 0."""
    actuation_ends: str = "clamped"
    """"clamped": only an actuator's interior triplets follow K̄(τ) (design §2.4 as written);
    "shared": each joint triplet also turns by the curvature change of the arc's half-edge
    beside the joint (design §2.7). Measured (`studies convergence`): still first order; it
    halves A1+A2's discretisation error but enlarges that of A1+A3, A1+A4, A1+A3+A5."""
    joint_radius: float = 0.024
    """Radius of the eight joints from the centre, m [recon]."""
    tip_radius: float = 0.052
    """Radius of the limb tips, m (diameter L = 104 mm); must exceed joint_radius."""
    n_arc: int = 18
    """Edges per actuator arc (topology: equal across a batch); >= 2."""
    n_limb: int = 6
    """Edges per foam limb (topology: equal across a batch); >= 1."""

    def __post_init__(self):
        parse_gait(self.gait)
        for name in ("youngs_modulus", "limb_stiffness_ratio", "period", "thickness",
                     "actuator_density", "foam_density", "fluid_density",
                     "cylinder_mass_per_height", "cylinder_diameter", "joint_radius",
                     "tip_radius"):
            _check_positive(name, getattr(self, name))
        for name in ("alpha", "added_mass_coeff", "drag_parallel", "drag_perpendicular",
                     "cylinder_drag", "cylinder_added_mass_coeff"):
            _check_non_negative(name, getattr(self, name))
        _check_choice("jet_mode", self.jet_mode, JET_MODES)
        _check_choice("actuation_ends", self.actuation_ends, ACTUATION_ENDS)
        _check_int_at_least("n_arc", self.n_arc, 2)
        _check_int_at_least("n_limb", self.n_limb, 1)
        if self.period <= PAPER_PROFILE.switch_time:
            raise ValueError(f"period must be > {PAPER_PROFILE.switch_time} s (the heating "
                             f"phase t0), got {self.period!r}")
        if self.tip_radius <= self.joint_radius:
            raise ValueError(f"tip_radius must be > joint_radius = {self.joint_radius} m "
                             f"(the limb points outwards), got {self.tip_radius!r}")
        largest_joint_radius = 1.0 / (PAPER_PROFILE.rest_curvature * math.sin(math.pi / 8))
        if self.joint_radius >= largest_joint_radius:
            raise ValueError(
                f"joint_radius must be < {largest_joint_radius:.6g} m: an actuator arc of rest "
                f"curvature {PAPER_PROFILE.rest_curvature:.5g} 1/m cannot span joints further "
                f"apart, got {self.joint_radius!r}")

    @classmethod
    def converged(cls, **fields) -> "StarParams":
        """StarParams at the converged discretisation (CONVERGED_DISCRETISATION), other fields
        as given."""
        return cls(**{**CONVERGED_DISCRETISATION, **fields})

    @property
    def limb_modulus(self) -> float:
        """E_limb, Pa."""
        return self.youngs_modulus * self.limb_stiffness_ratio

    @property
    def topology_key(self):
        """The fields that fix the topology; a batch must agree on them."""
        return (self.n_arc, self.n_limb)

    def replace(self, **changes) -> "StarParams":
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def field_names(cls):
        return [f.name for f in fields(cls)]


@dataclass(frozen=True)
class SolverConfig:
    """Time integration and Newton settings, shared by the batch."""

    dt: float = 1e-3
    """Time step h, s; > 0 and at most 1 s."""
    newton_tol: float = 1e-10
    """Convergence: max |Δq| of a Newton update, m; > 0 (f32 resolves ~4e-9 m, so >= 1e-7)."""
    max_newton: int = 25
    """Newton iterations per step before the instance is declared newton_failed; >= 1."""
    precision: str = "f64"
    """Floating point type of the engine: "f64" or "f32"."""
    integrator: str = "euler"
    """"euler": implicit Euler (paper Eq. 4, first order); "bdf2": second-order BDF (its first
    step, and the step after a retry, are implicit Euler)."""
    jacobian: str = "newton"
    """"newton": Newton–Raphson, a fresh Jacobian and LU every iteration (design §2.6);
    "chord": the step's first Jacobian is reused while it contracts the update ≥ 4× per
    iteration (same converged solution to newton_tol, fewer factorisations)."""
    max_substep_halvings: int = 4
    """A failed step is retried as 2, 4, ... 2^max_substep_halvings substeps before the instance
    is declared failed; 0 disables retries; >= 0."""

    def __post_init__(self):
        _check_positive("dt", self.dt)
        if self.dt > 1.0:
            raise ValueError(f"dt must be in (0, 1] s, got {self.dt!r}")
        _check_positive("newton_tol", self.newton_tol)
        _check_int_at_least("max_newton", self.max_newton, 1)
        _check_choice("precision", self.precision, PRECISIONS)
        _check_choice("integrator", self.integrator, INTEGRATORS)
        _check_choice("jacobian", self.jacobian, JACOBIANS)
        _check_int_at_least("max_substep_halvings", self.max_substep_halvings, 0)
        if self.precision == "f32" and self.newton_tol < 1e-7:
            raise ValueError(f"newton_tol must be >= 1e-7 m with precision 'f32' (its rounding "
                             f"of ~5 cm positions is ~4e-9 m), got {self.newton_tol!r}")
