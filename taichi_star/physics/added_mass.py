"""Added mass (paper Eq. 3): f_a = −ρ_f·C_a·r0·Δl·ẍ on every rod node (Δl its lumped rest
length), i.e. an extra diagonal mass; the cylinder gets ρ_f·C·π·D_c²/4 with its own coefficient
(0 by default: the paper gives the cylinder none). With the component heights on, a rod node's
added mass from its arc and limb edges scales with their heights over the hub's. It enters the
integrator's inertia, so it has no assembly of its own."""

import math

import numpy as np
import taichi as ti

from ..geometry import CENTRE
from .base import Term


@ti.data_oriented
class AddedMass(Term):
    name = "added_mass"
    linear_fields = ("added_mass_coeff", "cylinder_added_mass_coeff", "fluid_density")

    @staticmethod
    def configuration(coefficients):
        return None

    @staticmethod
    def added_inertia(params, topologies):
        fluid = np.array([p.fluid_density for p in params])
        # the arcs' and the limbs' lumped lengths, each times its height over the hub's
        lumped = (topologies.stack("lumped_length")
                  * np.array([p.height_ratios[::-1] for p in params])[:, None, :]).sum(axis=-1)
        added = (fluid * np.array([p.added_mass_coeff for p in params]))[:, None] \
            * np.array([p.thickness for p in params])[:, None] * lumped
        added[:, CENTRE] += fluid * np.array(
            [p.cylinder_added_mass_coeff * math.pi * p.cylinder_diameter ** 2 / 4 for p in params])
        return added
