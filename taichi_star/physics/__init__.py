"""The force terms, one module each, and the registry that lists them.

`TERMS` is the only list of terms: model building, loading to the device, compile-out and
assembly all iterate it, in this order (which is also the order in which forces are summed, and
the order of their `begin_step` hooks: the damping reads the natural curvatures the bending term
sets). Adding a term is one module plus one line here (and its NumPy twin in `reference.py`).

A term (`base.Term`) sees the batch only through the `assembly.Assembly` it is given: positions,
the integrator's rates, slot tables and the scatter of its residual and Jacobian; the elastic
terms share the strain-element base `strain.StrainTerm`, which the material damping reshapes
without knowing which terms they are. docs/numerics.md, "How a force term is written", explains
the interface.
"""

from .added_mass import AddedMass
from .bending import Bending
from .cylinder_drag import CylinderDrag
from .damping import MaterialDamping
from .jet import Jet
from .linear_drag import LinearDrag
from .rod_drag import RodDrag
from .stretching import Stretching
from .wake import Wake

TERMS = (AddedMass, Stretching, Bending, RodDrag, CylinderDrag, LinearDrag, Wake, Jet,
         MaterialDamping)


def coupled_node_pairs(topology, terms=TERMS):
    """Node pairs (i, j) whose 2×2 Jacobian block the given terms can fill: term classes
    (default: all, in their default configuration) or (class, configuration) pairs as in
    `model.BatchModel.terms_used`."""
    pairs = []
    for term in terms:
        cls, configuration = term if isinstance(term, tuple) else (term, ())
        pairs += cls.configured_pairs(topology, configuration)
    return pairs


__all__ = ["TERMS", "coupled_node_pairs"]
