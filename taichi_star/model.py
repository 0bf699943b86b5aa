"""The host model of a batch: every per-instance coefficient the kernels need, NumPy arrays with
a leading batch axis, built once from the StarParams by iterating the term registry and copied
to the device once."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, Sequence, Tuple

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
    def engine_key(self) -> Tuple:
        """What a compiled engine depends on: topology and the terms used with their switches."""
        return (self.params[0].topology_key,
                tuple((cls.name, configuration) for cls, configuration in self.terms_used))


def validate_batch(params) -> Tuple[StarParams, ...]:
    """The batch as a tuple (a single StarParams is a batch of one). Raises ValueError for an
    empty batch, a non-StarParams entry or instances whose topology (n_arc, n_limb) differs."""
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
    keys = {p.topology_key for p in params}
    if len(keys) > 1:
        raise ValueError(f"all instances of a batch must share n_arc and n_limb (the topology); "
                         f"got (n_arc, n_limb) in {sorted(keys)}")
    return params


def rest_topologies(params: Sequence[StarParams]):
    """One Topology per instance (shared between instances of the same rest geometry)."""
    shapes = {}
    for p in params:
        key = (p.joint_radius, p.tip_radius, p.actuator_profile.rest_curvature)
        if key not in shapes:
            shapes[key] = build_topology(p)
    return [shapes[(p.joint_radius, p.tip_radius, p.actuator_profile.rest_curvature)]
            for p in params]


def build_model(params: Sequence[StarParams], commanded: bool = False) -> BatchModel:
    """The host model of a batch (see `validate_batch` for the errors it raises). With
    `commanded`, the instances fire whatever they are commanded to (every actuator can fire),
    not their gait."""
    params = validate_batch(params)
    topologies = rest_topologies(params)
    topology = topologies[0]
    thickness = np.array([p.thickness for p in params])[:, None]
    lumped = np.stack([t.lumped_length for t in topologies])
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
                      rest_positions=np.stack([t.rest_positions for t in topologies]),
                      mass=mass, inertia=inertia, coefficients=coefficients,
                      terms_used=tuple(used))
