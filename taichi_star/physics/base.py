"""The interface every force term implements.

A term is one physical contribution to the residual of an implicit step and to its Jacobian.
Its class owns everything about it:

- `coefficients(params, topologies, topology)`: its per-instance coefficients on the host, NumPy
  arrays with a leading batch axis, computed from the StarParams and the per-instance rest
  geometry (`topologies`: one Topology per instance, whose `stack(name)` gathers a table of
  every instance; `topology`: the first one, for the shared structure);
  `commanded(coefficients)`: the same for a batch that fires what it is commanded;
- `configuration(coefficients)`: whether a batch uses it (None: compiled out) and the static
  switches of its kernel code (e.g. whether any instance is actuated);
- `coupled_pairs(topology)`: the node pairs whose 2×2 Jacobian blocks it can fill
  (`configured_pairs`: those of a given configuration, when its switches add some);
- `history(topology, terms)`: per-instance state it carries from step to step (e.g. the previous
  area of a jet space), saved and restored with the batch state. Most histories are recomputed
  from the positions at each step's start (`begin_step`), so a step redone from its start
  state finds them as they were. A term with `carries_state` keeps state that the positions do
  not determine (the velocity of the entrained water): it commits it in `accept_step` when the
  engine accepts a step (its own and its replicas'), and copies it in `copy_carried` when the
  engine keeps or restores the positions of a step it may redo in substeps;
- on the device, an instance of the class (a `ti.data_oriented` object) holds those coefficients
  and histories in fields with a leading batch axis, builds its index tables in `build` and
  assembles itself in `assemble`, both through the `assembly.Assembly` it is given (positions,
  the integrator's rates, the scatter into the residual and the Jacobian): a term never sees
  the engine.

A term may instead act on the elements of other terms (`reshapes`): the elements of a
`strain.StrainTerm` have the energy ½·k·(s − s⁰)² in a strain s, and a term that reshapes them
returns, from the (k, s⁰) of an element, the stiffness and target of the element's energy with
its own added. The material damping does this (its pseudo-energy has the elastic form), so each
element is evaluated and scattered into the Jacobian once, not once per term.

The engine never names a coefficient: it loads whatever `coefficients` returned into fields of
the same names and shapes.
"""

from typing import ClassVar, Dict, Optional, Sequence, Tuple

import numpy as np
import taichi as ti
from taichi.lang.util import to_numpy_type

from .assembly import Assembly


def numpy_to_field_type(array: np.ndarray):
    """The Taichi type of a field holding `array`: i32 for integers and booleans, else the
    runtime's default float (f64 or f32)."""
    return ti.i32 if array.dtype.kind in "biu" else float


def load_field(field, values: np.ndarray):
    """Copy `values` into `field`, cast to its type."""
    field.from_numpy(np.ascontiguousarray(values, dtype=to_numpy_type(field.dtype)))


def pad_batch(values: np.ndarray, capacity: int) -> np.ndarray:
    """Pad the batch axis up to capacity by repeating instance 0 (padding instances are
    inactive; repeating a real instance keeps every coefficient physical)."""
    padding = np.repeat(values[:1], capacity - len(values), axis=0)
    return np.concatenate([values, padding]) if len(padding) else values


class Term:
    """Base of the force terms; see the module docstring. Subclasses are `@ti.data_oriented`
    and implement `assemble` as a `@ti.func`."""

    name: ClassVar[str]
    carries_state: ClassVar[bool] = False
    """Whether the term keeps state the positions do not determine (`accept_step`,
    `copy_carried`); the engine compiles those calls only for a batch with such a term."""
    internal: ClassVar[bool] = False
    """Whether its forces are internal: the gradient of an energy that a rigid motion of the
    robot leaves unchanged (its net force and its net torque about any point vanish at every
    state). A sensitive engine leaves such terms out of the rigid-body equations of a tangent
    step (`engine.BatchEngine.rigid_correction`)."""
    reads_step_start: ClassVar[bool] = True
    """Whether its residual at given positions depends on the state at the step's start (the
    integrator's rates, velocities, histories carried from the last step). One that does not
    (an elastic energy) gives a sensitivities' replica the residual of its instance wherever
    their coefficients agree and no term that reads it reshapes the two (`start_reshapers`,
    `reshaping`; `engine.BatchEngine.replica_sameness`)."""
    pairs_linearly: ClassVar[bool] = False
    """Whether a sensitivities' replica's residual from it is the term at its instance's state
    plus a velocity derivative there times the replica's velocity offset (the expansion of
    `assembly.Assembly.primal_instance`), and nothing else of the replica's start state. Where
    the replica's coefficients of the term and its partner's are the instance's, the pair's
    half difference is then that derivative times half the pair's velocity difference: both
    replicas leave the term out (`engine.BatchEngine.replica_sameness`), and the tangent step
    adds `pair_difference(b, plus, minus, rate_gain, coefficients_differ)` instead, from the
    derivative the instance kept at its converged state (`assembly.KEEP_EXPANSION`). The same
    derivative within rounding: the sums run in another order."""
    linear_coefficients: ClassVar[Tuple[str, ...]] = ()
    """Its coefficients (names of `coefficients`) its residual is linear in, the state and its
    other coefficients given: each element's force is its value of them times a force of the
    state (a stiffness, a drag coefficient), with no other use of them. Where a sensitivities'
    replica pair differs from its instance in these alone (no term reshaping the elements of
    either, and the term, if it reads the step's start, pairing linearly), both replicas leave
    the term out too, and the tangent step's `pair_difference` (`coefficients_differ` 1) adds
    half the pair's difference of them times that force at the instance's converged state,
    besides any velocity part: the exact derivative, which the replicas' difference has to
    O(ε²) (the force is linear in them) from two assemblies of the term
    (`engine.BatchEngine.replica_sameness`)."""
    sensitivity_steps: ClassVar[Dict[str, float]] = {}
    """StarParams fields of this term whose sensitivities' ε (relative to the value) departs
    from `sensitivities.RELATIVE_STEP`, with the ε and, in the subclass, why
    (`sensitivities.FIELD_RELATIVE_STEPS` gathers them from `physics.TERMS`)."""
    linear_fields: ClassVar[Tuple[str, ...]] = ()
    """StarParams fields its forces are linear in (affine) or quadratic in, as a coefficient
    that scales them (α, a drag coefficient, the fluid's density, an actuator's gain), with
    no switch on the field's sign (a replica may lie below 0: the formulas must continue
    linearly or evenly there): a replica pair differences such a force exactly at any ε, so a
    value far below the field's usual one takes ε at least that of its usual scale
    (`sensitivities.LINEAR_FIELDS`). Not the damping time: `damping_time > 0` switches the
    damping on."""
    sensitivity_least_steps: ClassVar[Dict[str, float]] = {}
    """StarParams fields of this term whose sensitivities' ε has a least value (in the field's
    unit) where the relative one would be too small a move, with why in the subclass
    (`sensitivities.FIELD_LEAST_STEPS` gathers them): the term's force must then be smooth
    through the field's value ± that ε, beyond its range too."""
    fired_columns: ClassVar[Tuple[str, ...]] = ()
    """Its coefficients of one column per actuator ((B, 8), column k for A(k+1)) whose column k
    it reads only once actuator k has fired. A sensitivities' replica that differs from its
    instance in such a column alone keeps the instance's residual until that actuator first
    fires, so its tangent is exactly zero until then and the engine skips its work
    (`engine.BatchEngine.replica_waiting`)."""

    @staticmethod
    def coefficients(params: Sequence, topologies: Sequence, topology) -> Dict[str, np.ndarray]:
        """Per-instance coefficients: name -> array of shape (B, ...)."""
        return {}

    @staticmethod
    def commanded(coefficients: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
        """The coefficients of a batch whose instances fire whatever they are commanded, not
        their gait (`model.build_model(commanded=True)`): unchanged unless the term depends on
        the gait."""
        return coefficients

    @staticmethod
    def configuration(coefficients: Dict[str, np.ndarray]) -> Optional[Tuple]:
        """None when no instance of the batch needs the term (it is compiled out), else a
        hashable tuple of the static switches its kernel code takes."""
        return ()

    @staticmethod
    def coupled_pairs(topology) -> Sequence[Tuple[int, int]]:
        """Node pairs (i, j) whose Jacobian block the term can fill."""
        return ()

    @classmethod
    def configured_pairs(cls, topology, configuration: Tuple) -> Sequence[Tuple[int, int]]:
        """The node pairs the term can fill when compiled with `configuration` (default: the
        same as `coupled_pairs`; a term whose switches couple more nodes adds them)."""
        return cls.coupled_pairs(topology)

    @staticmethod
    def history(topology, terms: Sequence[type] = ()) -> Dict[str, Tuple[int, ...]]:
        """Per-instance state carried between steps: name -> per-instance shape. `terms`: the
        classes of the batch's terms (a term that reshapes others sizes its history by them)."""
        return {}

    @staticmethod
    def added_inertia(params: Sequence, topologies: Sequence) -> Optional[np.ndarray]:
        """(B, N) diagonal mass the term adds to the nodes' inertia (kg/m), or None."""
        return None

    @classmethod
    def reshapes(cls, other: type) -> bool:
        """Whether this term reshapes the elements of the term class `other` (`reshape`)."""
        return False

    @staticmethod
    def reshaping(coefficients: Dict[str, np.ndarray]) -> Optional[np.ndarray]:
        """For a term that reshapes others: (B,) bool, whether its `reshape` changes any element
        of each instance (with these coefficients); None: every instance's (the safe answer)."""
        return None

    def __init__(self, assembly: Assembly, configuration: Tuple,
                 coefficient_shapes: Dict[str, Tuple], terms: Sequence[type] = ()):
        """Device side: fields for the coefficients (shapes (capacity, ...)) and histories.
        `assembly` gives the batch's topology, state, integrator rates and linear system;
        `terms`: the classes of the batch's terms (as for `history`)."""
        self.assembly = assembly
        self.configuration_switches = configuration
        capacity = assembly.capacity
        self.coefficient_names = tuple(coefficient_shapes)
        for name, (shape, dtype) in coefficient_shapes.items():
            setattr(self, name, assembly.batch_field(dtype, (capacity,) + tuple(shape)))
        self.reshapers = []
        """The terms that reshape this term's elements (`connect_terms`)."""
        self.start_reshapers = []
        """The terms that reshape this term's elements and read the step's start: where one
        of them reshapes an instance (`reshaping`), this term's residual reads the step's
        start too (`connect_terms`)."""
        self.reshaped_terms = []
        """The terms whose elements this term reshapes (`connect_terms`)."""
        histories = self.history(assembly.topology, terms)
        self.history_names = tuple(histories)
        for name, shape in histories.items():
            setattr(self, name, assembly.batch_field(float, (capacity,) + tuple(shape)))
        self.build(assembly.topology)

    def build(self, topology):
        """Device tables of the topology the term needs (index fields, Jacobian slots, from
        `self.assembly`)."""

    def coefficient_fields(self) -> Dict[str, ti.Field]:
        """The device fields of the coefficients, by coefficient name."""
        return {name: getattr(self, name) for name in self.coefficient_names}

    def history_fields(self) -> Dict[str, ti.Field]:
        return {name: getattr(self, name) for name in self.history_names}

    @ti.func
    def begin_step(self, b, start_time, end_time, h, ratio, rate_gain, use_history):
        """Update the term's history at the start of a step of size h (s) from start_time to
        end_time, before the predictor moves the positions (a no-op by default)."""
        pass

    @ti.func
    def accept_step(self, b, rate_gain):
        """Commit the state carried over the step instance b has just converged and the engine
        has accepted (positions at its end; `rate_gain` that of the step): only with
        `carries_state`."""
        pass

    @ti.func
    def copy_carried(self, b, save):
        """Copy instance b's carried state into the term's backup (`save` = 1) or back from it
        (0), with the engine's backup of the positions: only with `carries_state`."""
        pass

    @ti.func
    def assemble(self, b, rate_gain, jacobian):
        """Add the term's residual (and, if `jacobian`, its Jacobian blocks) at the current
        iterate of instance b (a no-op for a term that only reshapes others)."""
        pass

    @ti.func
    def reshape(self, b, term: ti.template(), element, stiffness, target, rate_gain):
        """For a term class accepted by `reshapes`: (stiffness, target) of element `element` of
        `term` (instance b) → those of the element's energy with this term's added."""
        return stiffness, target

    @ti.func
    def reshaped(self, b, element, stiffness, target, rate_gain):
        """(stiffness, target) of this term's element `element` after every term that reshapes
        it (unchanged when none does)."""
        for reshaper in ti.static(self.reshapers):
            stiffness, target = reshaper.reshape(b, self, element, stiffness, target, rate_gain)
        return stiffness, target


def connect_terms(terms: Sequence[Term]):
    """Tell each of a batch's device terms which of the others reshape its elements and which
    it reshapes (by `Term.reshapes`, in registry order)."""
    for term in terms:
        term.reshapers = [other for other in terms if other.reshapes(type(term))]
        term.reshaped_terms = [other for other in terms if term.reshapes(type(other))]
        term.start_reshapers = [other for other in term.reshapers if other.reads_step_start]
