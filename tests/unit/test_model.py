"""The host model of a batch (`model.build_model`): each instance's tables are those it has
alone, whatever its neighbours, and the per-instance topologies (`InstanceTopologies`) share
one Topology per rest geometry. Values are compared exactly: building a model only gathers and
multiplies per-instance numbers, so batch position must not change a bit."""

import dataclasses
from dataclasses import fields

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from taichi_star import StarParams
from taichi_star import params as params_module
from taichi_star.geometry import Topology, build_topology
from taichi_star.model import InstanceTopologies, build_model

LARGEST_JOINT_RADIUS = 1.0 / (StarParams().actuator_profile.rest_curvature * np.sin(np.pi / 8))

BASE = StarParams(gait="A1+A3")
BATCH = [BASE,
         StarParams(gait="A2", joint_radius=0.022, tip_radius=0.05),
         StarParams(gait="A1+A3", alpha=1.3, hub_height=0.05, foam_height=0.02,
                    actuator_height=0.03, joint_stiffness="series"),
         StarParams(gait="A1", joint_radius=0.022, tip_radius=0.05, actuation_ends="shared"),
         BASE,
         StarParams(gait="A1", tip_radius=0.05),
         StarParams(gait="A2", actuator_profile=dataclasses.replace(
             StarParams().actuator_profile, heating=(-84.827, 62.724, 0.061, 104.040)))]
"""Seven instances of four rest geometries (the first, third and fifth share one; the second
and fourth another). The last two differ from the first in one of the rest shape's inputs
each, the tip radius and the profile's rest curvature: every other instance moved the joint
and the tip radius together, and a key of the shape without either passed every test (a
mutation audit, 2026-12: such an instance took another's rest shape, 1.85 mm off)."""


def test_instances_of_one_rest_geometry_share_one_topology():
    topologies = InstanceTopologies.of(BATCH)
    assert len(topologies) == len(BATCH)
    # the component heights leave the rest shape alone
    assert len(topologies.distinct) == 4
    assert topologies[0] is topologies[2] is topologies[4]
    assert topologies[1] is topologies[3] and topologies[1] is not topologies[0]
    assert len({id(topologies[b]) for b in (0, 1, 5, 6)}) == 4


def test_stack_equals_the_instances_own_topologies_one_by_one():
    topologies = InstanceTopologies.of(BATCH)
    own = [build_topology(p) for p in BATCH]
    arrays = [f.name for f in fields(Topology) if isinstance(getattr(own[0], f.name), np.ndarray)]
    assert "rest_positions" in arrays and "lumped_length" in arrays
    for name in arrays:
        assert np.array_equal(topologies.stack(name), np.stack([getattr(t, name) for t in own])), name


def assert_rows_are_their_instances_own(model, batch):
    """Each instance's rows of `model` (built from `batch`) are, bit for bit, those of the
    model of that instance alone, every table with the batch's leading axis."""
    for b, p in enumerate(batch):
        alone = build_model([p])
        for name in ("rest_positions", "mass", "inertia"):
            assert np.array_equal(getattr(model, name)[b], getattr(alone, name)[0]), name
        for term, table in alone.coefficients.items():
            for name, values in table.items():
                built = model.coefficients[term][name]
                assert built.shape == (len(batch),) + values.shape[1:], (term, name)
                assert np.array_equal(built[b], values[0]), (term, name)


def test_an_instances_model_tables_do_not_depend_on_its_batch():
    assert_rows_are_their_instances_own(build_model(BATCH), BATCH)


def test_the_engine_key_tells_apart_batches_whose_terms_are_switched_differently():
    """A compiled engine is reused for every batch of its key: robots that fire nothing and
    robots that fire, or a jet along the normal and the plain one, use their terms with other
    switches and need other engines (with the switches out of the key, an A1+A2 run after a
    gait "none" one reused its engine and moved -1.5e-14 mm instead of 0.136: a mutation
    audit, 2026-12). Equal switches share a key, other parameters or not."""
    def key(**fields):
        return build_model([StarParams(**fields)]).engine_key
    assert key(gait="none") != key(gait="A1")
    assert key(jet_direction="normal") != key()
    assert key(gait="A1", alpha=1.3) == key(gait="A1")


def test_the_memory_of_a_model_counts_each_of_its_arrays():
    model = build_model(BATCH)
    arrays = [model.rest_positions, model.mass, model.inertia] + [
        np.asarray(values) for table in model.coefficients.values() for values in table.values()]
    assert model.nbytes == sum(array.nbytes for array in arrays)


def test_a_batchs_topology_is_its_first_instances():
    np.testing.assert_array_equal(build_model(BATCH[1:]).topology.rest_positions,
                                  build_topology(BATCH[1]).rest_positions)


def test_a_series_joints_stiffness_comes_from_its_own_rest_shape():
    """The series joint's modulus weighs the joint triplet's arc and limb rest lengths; behind
    an instance of another rest geometry it took that instance's lengths (the batch's first
    topology) until 2026-12: its joints' bend stiffness 13 % off here."""
    series = BATCH[2]
    model = build_model([BATCH[1], series])
    alone = build_model([series])
    stiffness = model.coefficients["bending"]["bend_stiffness"]
    assert np.array_equal(stiffness[1], alone.coefficients["bending"]["bend_stiffness"][0])
    assert not np.array_equal(stiffness[1], build_model([series.replace(
        joint_radius=BATCH[1].joint_radius, tip_radius=BATCH[1].tip_radius)]).coefficients[
        "bending"]["bend_stiffness"][0])  # the other geometry's lengths give another stiffness


def test_equal_instances_are_built_once_with_their_tables_repeated_bit_for_bit():
    """A batch that repeats instances (equal objects, or the same object again; the order
    mixed) is built from its distinct instances and their tables repeated: every row is its
    instance's alone, bit for bit, the terms used are the batch's, and the model keeps the
    batch's own StarParams objects."""
    copies = [dataclasses.replace(p) for p in BATCH]  # equal, not the same objects
    order = [3, 0, 4, 1, 2, 0, 3, 1]
    batch = [(copies if i % 2 else BATCH)[k] for i, k in enumerate(order)]
    model = build_model(batch)
    assert all(kept is given for kept, given in zip(model.params, batch))
    assert model.terms_used == build_model(BATCH).terms_used
    assert_rows_are_their_instances_own(model, batch)


def test_every_parameter_takes_part_in_equality():
    """build_model builds instances equal as StarParams once: a field left out of equality
    (compare=False) would merge instances that differ in it."""
    from taichi_star.actuation import CurvatureProfile

    for cls in (StarParams, CurvatureProfile):
        assert [f.name for f in fields(cls) if not f.compare] == [], cls.__name__
    assert StarParams() != StarParams(actuator_profile=CurvatureProfile(switch_time=0.15))


def test_a_replica_models_tables_lie_on_their_instances_tangent():
    """`sensitivities.replica_model`: each replica pair's rest shape, masses and coefficients are
    its instance's ± one offset (symmetric to rounding), the offset ε times the tables'
    derivative by the parameter (against a central difference of the host's tables at a step
    of 1e-6 of the value: O(h²) ~1e-12 and rounding ~1e-10 relative, so 1e-8 of the largest
    offset); a pair built at p ± ε itself is not symmetric (its midpoint is ε²·c″/2 off, the
    misfit the linear model removes); and a table the parameter does not move stays the
    instance's, bit for bit (so the engine still leaves such a term out of the pair)."""
    from taichi_star.sensitivities import parse_directions, replica_batch, replica_model

    params = [StarParams.preset("paper"), StarParams.preset("paper").replace(gait="A1+A3")]
    directions = parse_directions(["joint_radius", "alpha"])
    model, steps = replica_model(params, directions)
    plain = build_model(replica_batch(params, directions)[0])
    count = len(params)
    pair = {"joint_radius": (slice(count, 2 * count), slice(2 * count, 3 * count)),
            "alpha": (slice(3 * count, 4 * count), slice(4 * count, 5 * count))}
    instance = model.rest_positions[:count]
    plus, minus = (model.rest_positions[s] for s in pair["joint_radius"])
    offset = plus - instance
    np.testing.assert_allclose(instance - minus, offset, rtol=0,
                               atol=1e-12 * np.abs(offset).max())
    h = 1e-6 * params[0].joint_radius
    moved = [build_model([p.replace(joint_radius=p.joint_radius + sign * h) for p in params])
             for sign in (1.0, -1.0)]
    derivative = (moved[0].rest_positions - moved[1].rest_positions) / (2 * h)
    np.testing.assert_allclose(offset / steps[0][:, None, None], derivative, rtol=0,
                               atol=1e-8 * np.abs(derivative).max())
    plain_plus, plain_minus = (plain.rest_positions[s] for s in pair["joint_radius"])
    assert np.abs(plain_plus + plain_minus - 2 * instance).max() > 1e-6 * np.abs(offset).max()
    # α moves the jet's coefficient only: the rest shape and the bending tables stay bitwise
    for side in pair["alpha"]:
        np.testing.assert_array_equal(model.rest_positions[side], instance)
        np.testing.assert_array_equal(model.coefficients["bending"]["voronoi_length"][side],
                                      model.coefficients["bending"]["voronoi_length"][:count])
    alpha_plus = model.coefficients["jet"]["jet_alpha"][pair["alpha"][0]]
    np.testing.assert_allclose(alpha_plus - model.coefficients["jet"]["jet_alpha"][:count],
                               steps[1], rtol=1e-9)


def unsigned(highest):
    """Floats in [0, highest] but the subnormal ones, which StarParams refuses (arithmetic
    flushes them to 0 once Taichi has started)."""
    return st.floats(0.0, highest, allow_subnormal=False)


@st.composite
def mixed_instance(draw):
    """StarParams differing in every field that shapes a table: rest geometry, every option,
    component heights on or off, the model extensions, per-actuator gains and delays."""
    joint_radius = draw(st.floats(0.015, 0.95 * LARGEST_JOINT_RADIUS))
    heights = draw(st.sampled_from([(0.0, 0.0, 0.0), (0.05, 0.024, 0.03), (0.03, 0.01, 0.02)]))
    period = draw(st.floats(0.5, 5.0))
    return StarParams(
        gait=draw(st.sampled_from(["A1", "A1+A3", "A2+A5+A8", "none"])),
        alpha=draw(unsigned(2.0)), youngs_modulus=draw(st.floats(1e6, 1e7)),
        limb_stiffness_ratio=draw(st.floats(1.0, 300.0)), thickness=draw(st.floats(2e-3, 5e-3)),
        period=period, joint_radius=joint_radius,
        tip_radius=joint_radius + draw(st.floats(0.015, 0.04)),
        cylinder_diameter=draw(st.floats(0.015, 0.04)),
        added_mass_coeff=draw(unsigned(3.0)), fluid_density=draw(st.floats(800.0, 1200.0)),
        jet_mode=draw(st.sampled_from(params_module.JET_MODES)),
        jet_direction=draw(st.sampled_from(params_module.JET_DIRECTIONS)),
        jet_application=draw(st.sampled_from(params_module.JET_APPLICATIONS)),
        actuation_ends=draw(st.sampled_from(params_module.ACTUATION_ENDS)),
        joint_stiffness=draw(st.sampled_from(params_module.JOINT_STIFFNESSES)),
        profile_closure=draw(st.sampled_from(("jump", "ramp"))),
        damping_time=draw(st.sampled_from([0.0, 1e-3])),
        hub_height=heights[0], foam_height=heights[1], actuator_height=heights[2],
        linear_drag=draw(st.sampled_from([0.0, 5.0])),
        wake_coupling=draw(st.sampled_from([0.0, 2.0])),
        actuator_gains=tuple(draw(st.lists(unsigned(2.0), min_size=8, max_size=8))),
        actuator_delays=tuple(draw(st.lists(unsigned(0.9 * period), min_size=8, max_size=8))))


@settings(max_examples=25, deadline=None)
@given(batch=st.lists(mixed_instance(), min_size=2, max_size=4), data=st.data())
def test_every_table_of_a_mixed_batch_is_its_instances_own(batch, data):
    """Whatever the other instances (any geometry, option or extension, in any order, some
    repeated), each instance's rows of the host model are those it has alone, bit for bit: the
    engine's kernels read an instance's own rows only, so its motion is then its own too. The
    series joints' stiffness from the batch's first rest shape broke this (2026-12)."""
    batch = batch + [batch[0]]
    order = data.draw(st.permutations(range(len(batch))))
    batch = [batch[k] for k in order]
    assert_rows_are_their_instances_own(build_model(batch), batch)
