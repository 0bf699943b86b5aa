"""The strain-element base of the elastic terms (stretching, bending).

Each element of a `StrainTerm` stores the energy ½·k·(s − s⁰)² (J/m) in one strain s of its
nodes: ε = |e|/Δl̄ − 1 of an edge (k = E·r0·Δl̄), the curvature κ of a triplet (k = (E·r0³/12)·Δl,
s⁰ = κ⁰). The base assembles any such term the same way: per element, its stiffness k and target
s⁰, passed through the terms that reshape the element (the material damping: `Term.reshapes`),
then the element's energy derivatives at that (k, s⁰), scattered into the residual and the
Jacobian. A term that reshapes strain elements reads them only through this interface
(`strain`, `natural_strain`, `n_elements`), whatever the strain is.

A subclass gives
- `element_count(topology)`: elements per instance (host; sets the shapes of the histories of
  the terms that reshape it) and `n_elements` (the same, set in `build`);
- `stiffness(b, e)` (its elastic k, in the units of its `add_element`), `natural_strain(b, e,
  at_start)` (s⁰ at the start of the current step, at_start = 1, or at its end) and
  `strain(b, e)` (s at instance b's current positions), all `@ti.func`;
- `add_element(b, e, stiffness, target, jacobian)`: the gradient and Hessian of the element's
  energy with that stiffness and target, with respect to its nodes, added through the
  `Assembly` (each term writes them in its own closed form, whose rounding the committed results
  depend on; `reference.py` gives the same energies as strain, strain gradient and strain
  Hessian composed by `quadratic_strain_element`).
"""

import taichi as ti

from .base import Term


@ti.data_oriented
class StrainTerm(Term):
    """Base of the terms made of strain elements; see the module docstring for what a
    subclass gives (`stiffness`, `strain`, `add_element` have no default)."""

    n_elements: int
    reads_step_start = False  # k and s⁰ come from the coefficients, the time and the firings
    internal = True  # an energy of strains: edge lengths and turning angles

    @staticmethod
    def element_count(topology) -> int:
        """Elements per instance."""
        raise NotImplementedError

    @ti.func
    def natural_strain(self, b, e, at_start):
        """s⁰ of element e of instance b at the start (at_start = 1) or the end of the step
        (0 unless the subclass says otherwise)."""
        return 0.0

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        for e in range(self.n_elements):
            stiffness, target = self.reshaped(b, e, self.stiffness(b, e),
                                              self.natural_strain(b, e, 0), rate_gain)
            self.add_element(b, e, stiffness, target, jacobian)

    @ti.func
    def pair_difference(self, b, plus, minus, rate_gain, coefficients_differ):
        """Add to rhs[b] half the difference of the residuals of replicas `plus` and `minus`
        of simulated instance b, which differ from b in their stiffnesses alone
        (`coefficients_differ`; else in nothing, and their difference is zero): the energy is
        linear in k, so each element's gradient at b's positions and target with half the
        pair's difference of k as its stiffness (no term reshapes the elements of either:
        `Term.linear_coefficients`)."""
        if coefficients_differ:
            for e in range(self.n_elements):
                half_difference = 0.5 * (self.stiffness(plus, e) - self.stiffness(minus, e))
                if half_difference != 0.0:
                    self.add_element(b, e, half_difference, self.natural_strain(b, e, 0), 0)
