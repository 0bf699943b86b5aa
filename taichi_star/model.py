"""The host model of a batch: every per-instance coefficient the kernels need, NumPy arrays with
a leading batch axis, built once from the StarParams by iterating the term registry and copied
to the device once."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

import numpy as np

from .geometry import CENTRE, Topology, build_topology
from .params import StarParams
from .physics import TERMS


@dataclass(frozen=True)
class BatchModel:
    """Shapes: B instances, N nodes. SI units throughout."""

    params: Tuple[StarParams, ...]
    topology: Topology
    """Shared structure (from the first instance; per-instance rest geometry is below)."""
    rest_positions: np.ndarray
    """(B, N, 2) rest shape, m."""
    mass: np.ndarray
    """(B, N) lumped structural mass, kg/m (per hub height when the component heights are on;
    the centroid's weights)."""
    inertia: np.ndarray
    """(B, N) mass plus the terms' added mass, kg/m (the diagonal mass of the inertia term)."""
    coefficients: Dict[str, Dict[str, np.ndarray]]
    """Per term name: its coefficients, name -> (B, ...) array."""
    terms_used: Tuple
    """(term class, configuration) of the terms some instance uses, in registry order."""

    @property
    def batch_size(self) -> int:
        return len(self.params)

    @property
    def nbytes(self) -> int:
        """Host memory of the per-instance arrays (rest shape, masses, coefficients), bytes."""
        return (self.rest_positions.nbytes + self.mass.nbytes + self.inertia.nbytes
                + sum(np.asarray(values).nbytes for table in self.coefficients.values()
                      for values in table.values()))

    @property
    def engine_key(self) -> Tuple:
        """What a compiled engine depends on: topology and the terms used with their switches."""
        return (self.params[0].topology_key,
                tuple((cls.name, configuration) for cls, configuration in self.terms_used))


def instances_of(params) -> Tuple[StarParams, ...]:
    """The instances of a batch as a tuple (a single StarParams is a batch of one). Raises
    ValueError for what is not a sequence, an empty batch or a non-StarParams entry."""
    if isinstance(params, StarParams):
        return (params,)
    if params is None or isinstance(params, (str, bytes)) or not hasattr(params, "__iter__"):
        raise ValueError(f"params must be a sequence of StarParams, got {type(params).__name__}")
    params = tuple(params)
    if not params:
        raise ValueError("params must hold at least one StarParams (the batch is empty)")
    for index, p in enumerate(params):
        if not isinstance(p, StarParams):
            raise ValueError(f"params[{index}] must be a StarParams, got {type(p).__name__}")
    return params


def validate_batch(params) -> Tuple[StarParams, ...]:
    """The batch of one engine as a tuple (`instances_of`). Raises ValueError as that does and
    for instances whose topology (n_arc, n_limb) differs."""
    params = instances_of(params)
    keys = {p.topology_key for p in params}
    if len(keys) > 1:
        raise ValueError(f"all instances of a batch must share n_arc and n_limb (the topology); "
                         f"got (n_arc, n_limb) in {sorted(keys)}: run_batch runs such a batch, "
                         f"an engine for each topology")
    return params


class InstanceTopologies(Sequence[Topology]):
    """One Topology per instance of a batch, shared between the instances of the same rest
    geometry: a sequence of B Topology objects whose `stack` gathers a per-instance table
    without touching every instance (a batch of 65,536 has one or a few geometries)."""

    def __init__(self, distinct: Sequence[Topology], index: Optional[np.ndarray] = None):
        self.distinct = tuple(distinct)
        """The distinct topologies."""
        self.index = (np.arange(len(self.distinct)) if index is None
                      else np.asarray(index, dtype=np.int64))
        """(B,) int64: the position in `distinct` of each instance's topology (default: one
        instance per topology)."""

    @classmethod
    def of(cls, params: Sequence[StarParams]) -> "InstanceTopologies":
        """The topologies of a batch, each built once per distinct rest geometry."""
        position: Dict[Tuple, int] = {}
        index = np.empty(len(params), dtype=np.int64)
        built = []
        for b, p in enumerate(params):
            key = (p.joint_radius, p.tip_radius, p.actuator_profile.rest_curvature)
            if key not in position:
                position[key] = len(built)
                built.append(build_topology(p))
            index[b] = position[key]
        return cls(built, index)

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, b):
        if isinstance(b, slice):
            return [self.distinct[k] for k in self.index[b]]
        return self.distinct[self.index[b]]

    def stack(self, attribute: str) -> np.ndarray:
        """(B, ...) the Topology array `attribute` of every instance (a copy): the same values
        as stacking them one by one."""
        return np.stack([getattr(t, attribute) for t in self.distinct])[self.index]


def build_model(params: Sequence[StarParams], commanded: bool = False) -> BatchModel:
    """The host model of a batch (see `validate_batch` for the errors it raises). With
    `commanded`, the instances fire whatever they are commanded to (every actuator can fire),
    not their gait. Instances equal as StarParams (a batch that repeats a few gaits, the
    replicas of such instances) are built once and their tables repeated: every table is a
    function of its own instance's parameters alone, so the values are those of building each
    (`tests/unit/test_model.py`)."""
    params = validate_batch(params)
    position: Dict[StarParams, int] = {}
    index = np.array([position.setdefault(p, len(position)) for p in params], dtype=np.int64)
    if len(position) == len(params):
        return _build_distinct(params, commanded)
    distinct = _build_distinct(tuple(position), commanded)
    return dataclasses.replace(
        distinct, params=params, rest_positions=distinct.rest_positions[index],
        mass=distinct.mass[index], inertia=distinct.inertia[index],
        coefficients={name: {key: values[index] for key, values in table.items()}
                      for name, table in distinct.coefficients.items()})


MASS_FIELDS = ("actuator_density", "foam_density", "cylinder_mass_per_height")
"""The StarParams fields the nodes' own masses are linear in (`_build_distinct`; the terms'
added masses declare theirs: `physics.base.Term.linear_fields`)."""


def _build_distinct(params: Tuple[StarParams, ...], commanded: bool) -> BatchModel:
    """`build_model` of a validated batch, instance by instance."""
    topologies = InstanceTopologies.of(params)
    topology = topologies[0]
    thickness = np.array([p.thickness for p in params])[:, None]
    lumped = topologies.stack("lumped_length")
    # each rod component's mass per hub height (its density times its height over the hub's)
    mass = thickness * (np.array([p.actuator_density * p.height_ratios[1]
                                  for p in params])[:, None] * lumped[:, :, 0]
                        + np.array([p.foam_density * p.height_ratios[0]
                                    for p in params])[:, None] * lumped[:, :, 1])
    mass[:, CENTRE] += np.array([p.cylinder_mass_per_height for p in params])
    inertia = mass
    coefficients, used = {}, []
    for cls in TERMS:
        added = cls.added_inertia(params, topologies)
        if added is not None:
            inertia = inertia + added
        coefficients[cls.name] = cls.coefficients(params, topologies, topology)
        if commanded:
            coefficients[cls.name] = cls.commanded(coefficients[cls.name])
        configuration = cls.configuration(coefficients[cls.name])
        if configuration is not None:
            used.append((cls, configuration))
    return BatchModel(params=params, topology=topology,
                      rest_positions=topologies.stack("rest_positions"),
                      mass=mass, inertia=inertia, coefficients=coefficients,
                      terms_used=tuple(used))
