"""The host model of a batch: every per-instance coefficient the kernels need, in NumPy arrays
with a leading batch axis, built once from the StarParams and copied to the device once."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .gait import N_ACTUATORS, Gait
from .geometry import ARC, SPOKE, ARC_BEND, Topology, build_topology
from .params import StarParams


@dataclass(frozen=True)
class BatchModel:
    """Shapes: B instances, N nodes, E edges, T triplets. SI units throughout."""

    params: tuple
    topology: Topology
    """Shared structure (from the first instance; per-instance rest geometry is below)."""
    rest_positions: np.ndarray
    """(B, N, 2) m."""
    rest_length: np.ndarray
    """(B, E) m."""
    voronoi_length: np.ndarray
    """(B, T) m."""
    rest_curvature: np.ndarray
    """(B, T) 1/m."""
    end_turning_length: np.ndarray
    """(B, T) m: Topology.end_turning_length where actuation_ends is "shared", else 0."""
    edge_stiffness: np.ndarray
    """(B, E) E·r0, N/m·m = N per unit height."""
    bend_stiffness: np.ndarray
    """(B, T) E·r0³/12, N·m²."""
    drag_parallel_coeff: np.ndarray
    """(B, E) ½·ρ_f·Δl̄·C∥ (0 on spokes), kg/m² per unit height."""
    drag_perpendicular_coeff: np.ndarray
    """(B, E) ½·ρ_f·Δl̄·C⊥ (0 on spokes)."""
    mass: np.ndarray
    """(B, N) lumped structural mass, kg/m (centroid weights)."""
    inertia: np.ndarray
    """(B, N) mass + added mass, kg/m (the diagonal of M in Eq. 4)."""
    cylinder_drag_coeff: np.ndarray
    """(B,) ½·ρ_f·C_c·D_c, kg/m²."""
    jet_alpha: np.ndarray
    """(B,) α."""
    fluid_density: np.ndarray
    """(B,) ρ_f, kg/m³."""
    jet_always: np.ndarray
    """(B,) int32: 1 for jet_mode "always"."""
    period: np.ndarray
    """(B,) s."""
    gait_mask: np.ndarray
    """(B, 8) int32."""

    @property
    def batch_size(self) -> int:
        return len(self.params)

    @property
    def uses_jet(self) -> bool:
        return bool((self.jet_alpha > 0).any())

    @property
    def uses_rod_drag(self) -> bool:
        return bool((self.drag_parallel_coeff > 0).any() or (self.drag_perpendicular_coeff > 0).any())

    @property
    def uses_cylinder_drag(self) -> bool:
        return bool((self.cylinder_drag_coeff > 0).any())

    @property
    def uses_actuation(self) -> bool:
        return bool(self.gait_mask.any())


def build_model(params: Sequence[StarParams]) -> BatchModel:
    """The host model of a batch. Raises ValueError for an empty batch, a non-StarParams entry or
    instances whose topology (n_arc, n_limb) differs."""
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
    shapes = {}
    for p in params:
        key = (p.joint_radius, p.tip_radius, p.actuator_profile.rest_curvature)
        if key not in shapes:
            shapes[key] = build_topology(p)
    topologies = [shapes[(p.joint_radius, p.tip_radius, p.actuator_profile.rest_curvature)]
                  for p in params]
    topology = topologies[0]

    def stack(name):
        return np.stack([getattr(t, name) for t in topologies])

    def per_instance(function):
        return np.array([function(p) for p in params], dtype=np.float64)

    thickness = per_instance(lambda p: p.thickness)[:, None]
    arc_edge = topology.edge_kind == ARC
    arc_triplet = topology.triplet_kind == ARC_BEND
    modulus_edge = np.where(arc_edge, per_instance(lambda p: p.youngs_modulus)[:, None],
                            per_instance(lambda p: p.limb_modulus)[:, None])
    modulus_triplet = np.where(arc_triplet, per_instance(lambda p: p.youngs_modulus)[:, None],
                               per_instance(lambda p: p.limb_modulus)[:, None])
    rest_length = stack("rest_length")
    fluid_density = per_instance(lambda p: p.fluid_density)
    wetted = (topology.edge_kind != SPOKE)[None, :] * 0.5 * fluid_density[:, None] * rest_length

    lumped = stack("lumped_length")
    mass = thickness * (per_instance(lambda p: p.actuator_density)[:, None] * lumped[:, :, 0]
                        + per_instance(lambda p: p.foam_density)[:, None] * lumped[:, :, 1])
    mass[:, 0] += per_instance(lambda p: p.cylinder_mass_per_height)
    added = (fluid_density * per_instance(lambda p: p.added_mass_coeff))[:, None] * thickness \
        * lumped.sum(axis=2)
    added[:, 0] += fluid_density * per_instance(
        lambda p: p.cylinder_added_mass_coeff * math.pi * p.cylinder_diameter ** 2 / 4)

    return BatchModel(
        params=params, topology=topology,
        rest_positions=stack("rest_positions"), rest_length=rest_length,
        voronoi_length=stack("voronoi_length"), rest_curvature=stack("rest_curvature"),
        end_turning_length=stack("end_turning_length") * np.array(
            [p.actuation_ends == "shared" for p in params], dtype=np.float64)[:, None],
        edge_stiffness=modulus_edge * thickness,
        bend_stiffness=modulus_triplet * thickness ** 3 / 12.0,
        drag_parallel_coeff=wetted * per_instance(lambda p: p.drag_parallel)[:, None],
        drag_perpendicular_coeff=wetted * per_instance(lambda p: p.drag_perpendicular)[:, None],
        mass=mass, inertia=mass + added,
        cylinder_drag_coeff=0.5 * fluid_density * per_instance(
            lambda p: p.cylinder_drag * p.cylinder_diameter),
        jet_alpha=per_instance(lambda p: p.alpha), fluid_density=fluid_density,
        jet_always=np.array([p.jet_mode == "always" for p in params], dtype=np.int32),
        period=per_instance(lambda p: p.period),
        gait_mask=np.stack([Gait.parse(p.gait).mask for p in params]).astype(np.int32).reshape(
            len(params), N_ACTUATORS),
    )

