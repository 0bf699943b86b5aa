"""The host model of a batch (`model.build_model`): each instance's tables are those it has
alone, whatever its neighbours, and the per-instance topologies (`InstanceTopologies`) share
one Topology per rest geometry. Values are compared exactly: building a model only gathers and
multiplies per-instance numbers, so batch position must not change a bit."""

from dataclasses import fields

import numpy as np

from taichi_star import StarParams
from taichi_star.geometry import Topology, build_topology
from taichi_star.model import InstanceTopologies, build_model

BASE = StarParams(gait="A1+A3")
BATCH = [BASE,
         StarParams(gait="A2", joint_radius=0.022, tip_radius=0.05),
         StarParams(gait="A1+A3", alpha=1.3, hub_height=0.05, foam_height=0.02,
                    actuator_height=0.03, joint_stiffness="series"),
         StarParams(gait="A1", joint_radius=0.022, tip_radius=0.05, actuation_ends="shared"),
         BASE]
"""Five instances of three rest geometries (the first, third and fifth share one)."""


def test_instances_of_one_rest_geometry_share_one_topology():
    topologies = InstanceTopologies.of(BATCH)
    assert len(topologies) == len(BATCH)
    assert len(topologies.distinct) == 2  # the component heights leave the rest shape alone
    assert topologies[0] is topologies[2] is topologies[4]
    assert topologies[1] is topologies[3] and topologies[1] is not topologies[0]


def test_stack_equals_the_instances_own_topologies_one_by_one():
    topologies = InstanceTopologies.of(BATCH)
    own = [build_topology(p) for p in BATCH]
    arrays = [f.name for f in fields(Topology) if isinstance(getattr(own[0], f.name), np.ndarray)]
    assert "rest_positions" in arrays and "lumped_length" in arrays
    for name in arrays:
        assert np.array_equal(topologies.stack(name), np.stack([getattr(t, name) for t in own])), name


def test_an_instances_model_tables_do_not_depend_on_its_batch():
    batch = build_model(BATCH)
    for b, p in enumerate(BATCH):
        alone = build_model([p])
        for name in ("rest_positions", "mass", "inertia"):
            assert np.array_equal(getattr(batch, name)[b], getattr(alone, name)[0]), name
        for term, table in alone.coefficients.items():
            for name, values in table.items():
                assert np.array_equal(batch.coefficients[term][name][b], values[0]), (term, name)
