"""Shape checks of taichi_star.metrics on hand-made shapes: limb crossing, arc inversion,
strain, failed records; and the segment-crossing test they rest on."""

import numpy as np
import pytest

from taichi_star import StarParams
from taichi_star import metrics
from taichi_star.geometry import build_topology


@pytest.fixture(scope="module")
def topology():
    return build_topology(StarParams())


def test_limb_and_arc_chains_run_joint_to_tip_and_joint_to_joint(topology):
    assert topology.limbs.shape == (8, StarParams().n_limb + 1)
    assert list(topology.limbs[:, 0]) == list(topology.joints)
    assert list(topology.limbs[:, -1]) == list(topology.tips)
    radii = np.linalg.norm(topology.rest_positions[topology.limbs], axis=-1)
    assert (np.diff(radii, axis=1) > 0).all()  # straight radial limbs, outwards
    assert list(topology.arcs[:, -1]) == list(np.roll(topology.joints, -1))


def test_rest_shape_is_sane(topology):
    rest = topology.rest_positions
    row = metrics.shape_checks(rest[None, None], topology).iloc[0]
    assert not row["limbs_cross"] and not row["arc_inverted"] and row["finite"] and row["sane"]
    assert row["max_strain"] < 1e-12  # the rest shape defines the rest lengths
    # every arc bulges the same way at rest, with the actuators' rest curvature 102.12 1/m up
    # to the discrete curvature of the chords (n_arc 18: well within 1 %)
    mean = metrics.arc_mean_curvature(rest, topology)
    assert np.allclose(np.abs(mean), 102.12, rtol=1e-2)
    assert len(set(np.sign(mean))) == 1


def test_crossed_limbs_are_detected_in_any_record(topology):
    shape = topology.rest_positions.copy()
    limb0, limb1 = topology.limbs[0], topology.limbs[1]
    # swing limb 0's last segment through the middle of a segment of limb 1
    middle = 0.5 * (shape[limb1[2]] + shape[limb1[3]])
    before_tip = shape[limb0[-2]]
    shape[limb0[-1]] = before_tip + 2.0 * (middle - before_tip)
    assert metrics.limbs_cross(shape, topology)
    assert not metrics.limbs_cross(topology.rest_positions, topology)
    final = metrics.shape_checks(np.stack([topology.rest_positions, shape])[:, None],
                                 topology).iloc[0]
    assert final["limbs_cross"] and final["limbs_cross_final"] and not final["sane"]
    earlier = metrics.shape_checks(np.stack([shape, topology.rest_positions])[:, None],
                                   topology).iloc[0]
    assert earlier["limbs_cross"] and not earlier["limbs_cross_final"] and not earlier["sane"]


def test_limbs_bent_towards_each_other_without_touching_do_not_cross(topology):
    shape = topology.rest_positions.copy()
    limb0, limb1 = topology.limbs[0], topology.limbs[1]
    middle = 0.5 * (shape[limb1[2]] + shape[limb1[3]])
    before_tip = shape[limb0[-2]]
    shape[limb0[-1]] = before_tip + 0.9 * (middle - before_tip)  # stops short of limb 1
    assert not metrics.limbs_cross(shape, topology)


def first_arc_inverted(topology):
    """The rest shape with arc 0's interior nodes reflected across its chord: lengths are kept,
    the bulge flips outwards, so the strain check cannot be what flags it."""
    shape = topology.rest_positions.copy()
    interior = topology.arcs[0, 1:-1]
    a, b = shape[topology.arcs[0, 0]], shape[topology.arcs[0, -1]]
    direction = (b - a) / np.linalg.norm(b - a)
    offset = shape[interior] - a
    shape[interior] = a + 2.0 * (offset @ direction)[:, None] * direction - offset
    return shape


def test_an_inverted_arc_is_detected(topology):
    shape = first_arc_inverted(topology)
    mean = metrics.arc_mean_curvature(shape, topology)
    rest = metrics.arc_mean_curvature(topology.rest_positions, topology)
    assert mean[0] * rest[0] < 0 and (mean[1:] * rest[1:] > 0).all()
    row = metrics.shape_checks(shape[None, None], topology).iloc[0]
    assert row["arc_inverted"] and not row["limbs_cross"] and not row["sane"]
    assert row["max_strain"] < 1e-12


def test_large_strain_alone_is_not_sane(topology):
    # a uniform 1.6x blow-up: nothing crosses, no arc inverts, every edge has ε = 0.6
    row = metrics.shape_checks((1.6 * topology.rest_positions)[None, None], topology).iloc[0]
    assert not row["limbs_cross"] and not row["arc_inverted"]
    assert row["max_strain"] == pytest.approx(0.6, rel=1e-9)
    assert not row["sane"]


def test_records_after_a_failure_are_skipped(topology):
    rest = topology.rest_positions
    failed = np.full_like(rest, np.nan)
    checks = metrics.shape_checks(np.stack([np.stack([rest, rest]), np.stack([rest, failed])]),
                                  topology)
    assert checks["sane"].tolist() == [True, False]
    assert checks["finite"].tolist() == [True, False]
    assert not checks["limbs_cross"].iloc[1] and not checks["arc_inverted"].iloc[1]
    assert not checks["arc_inverted_final"].iloc[1]
    assert checks["max_strain"].iloc[1] < 1e-12


P = np.array


@pytest.mark.parametrize("p,q,r,s,expected", [
    (P([0, 0]), P([1, 1]), P([0, 1]), P([1, 0]), True),          # an X
    (P([0, 0]), P([1, 0]), P([0.5, 0]), P([0.5, 1]), False),     # T: touching is not crossing
    (P([0, 0]), P([1, 0]), P([0.5, 0.1]), P([0.5, 1]), False),   # stops short
    (P([0, 0]), P([1, 0]), P([2, 0]), P([3, 0]), False),         # collinear, disjoint
    (P([0, 0]), P([1, 0]), P([-1, 0]), P([-2, 0]), False),       # collinear, opposite sides
    (P([0, 0]), P([1, 0]), P([0.5, 0]), P([2, 0]), True),        # collinear, overlapping
    (P([0, 0]), P([1, 0]), P([0, 1e-3]), P([1, 1e-3]), False),   # parallel, offset
])
def test_segments_cross(p, q, r, s, expected):
    p, q, r, s = (np.asarray(v, dtype=float) for v in (p, q, r, s))
    assert bool(metrics.segments_cross(p, q, r, s)) == expected
    # symmetric in the two segments and in their directions
    assert bool(metrics.segments_cross(r, s, p, q)) == expected
    assert bool(metrics.segments_cross(q, p, s, r)) == expected


def test_point_symmetric_collinear_segments_do_not_cross(topology):
    # Opposite limbs of the symmetric all-eight gait stay straight and point-symmetric, so they
    # are collinear; a plain orientation-sign test flags such pairs as crossed by rounding
    # (±1e-20 orientations of alternating sign). 5000 random such pairs:
    rng = np.random.default_rng(1)
    angle = rng.uniform(0, 2 * np.pi, 5000)
    direction = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    inner = rng.uniform(0.024, 0.05, 5000)[:, None]
    outer = inner + rng.uniform(0.002, 0.006, 5000)[:, None]
    p, q = inner * direction, outer * direction
    assert not metrics.segments_cross(p, q, -p, -q).any()
    symmetric = topology.rest_positions.copy()
    symmetric[topology.limbs[4:]] = -symmetric[topology.limbs[:4]]
    assert not metrics.limbs_cross(symmetric, topology)


def test_strain_is_measured_against_each_instances_own_rest_shape():
    """Two robots of different geometry in their rest shapes: zero strain against their own
    rest shapes; against the first one's rest lengths the second shows its size difference."""
    import taichi_star as ts
    from taichi_star.model import build_model

    model = build_model([ts.StarParams(), ts.StarParams(joint_radius=0.022, tip_radius=0.05)])
    own = metrics.shape_checks(model.rest_positions[None], model.topology, model.rest_positions)
    assert own.max_strain.max() <= 1e-12  # round-off of the rest-shape construction
    shared = metrics.shape_checks(model.rest_positions[None], model.topology)
    assert shared.max_strain.iloc[0] <= 1e-12 and shared.max_strain.iloc[1] > 0.05


def _crossing_by_orientations(p, q, r, s):
    """Independent exact rule for integer points: a proper crossing has each segment's ends on
    strictly opposite sides of the other; collinear segments cross where their extents along
    the line overlap with positive length; touching at an end or parallel apart is no crossing."""
    def orientation(a, b, c):
        return np.sign((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))

    o1, o2 = orientation(p, q, r), orientation(p, q, s)
    o3, o4 = orientation(r, s, p), orientation(r, s, q)
    if o1 == o2 == o3 == o4 == 0:
        axis = 0 if p[0] != q[0] else 1
        low = max(min(p[axis], q[axis]), min(r[axis], s[axis]))
        high = min(max(p[axis], q[axis]), max(r[axis], s[axis]))
        return high > low
    return o1 * o2 < 0 and o3 * o4 < 0


def test_segments_cross_matches_an_exact_orientation_rule_on_a_small_grid():
    """2,000 random segment pairs with integer ends in [0, 4]² (many collinear, touching and
    parallel cases), evaluated as one batch: every classification matches the exact rule."""
    rng = np.random.default_rng(7)
    points = rng.integers(0, 5, size=(4, 2000, 2)).astype(float)
    keep = ~(np.all(points[0] == points[1], axis=-1) | np.all(points[2] == points[3], axis=-1))
    p, q, r, s = points[:, keep]
    batch = metrics.segments_cross(p, q, r, s)
    expected = [_crossing_by_orientations(*ends) for ends in zip(p, q, r, s)]
    np.testing.assert_array_equal(batch, expected)
    assert 50 < batch.sum() < len(batch) - 50  # both outcomes well represented


@pytest.mark.parametrize("length", [1e-3, 1.0, 1e3])
def test_nearly_collinear_overlapping_segments_cross_at_any_scale(length):
    """Two overlapping segments on one line, the second turned by 1e-12 rad about its start:
    parallel within the relative tolerance (1e-9) at every length, so they cross by overlap;
    shifted off the line by 1e-6 of their length they do not."""
    angle = 1e-12
    p, q = np.array([0.0, 0.0]), np.array([length, 0.0])
    r = np.array([0.5 * length, 0.0])
    s = r + 1.5 * length * np.array([np.cos(angle), np.sin(angle)])
    assert metrics.segments_cross(p, q, r, s)
    off = np.array([0.0, 1e-6 * length])
    assert not metrics.segments_cross(p, q, r + off, s + off)


def test_each_pair_of_a_batch_is_judged_parallel_at_its_own_scale():
    """A tiny perpendicular crossing (1e-4 m) next to a huge pair (1e6 m) in one batch: the
    parallel tolerance is relative to each pair's own lengths, so the tiny pair still crosses."""
    p = np.array([[0.0, 0.0], [0.0, 0.0]])
    q = np.array([[1e-4, 0.0], [1e6, 0.0]])
    r = np.array([[5e-5, -5e-5], [0.0, 1.0]])
    s = np.array([[5e-5, 5e-5], [1e6, 2.0]])
    np.testing.assert_array_equal(metrics.segments_cross(p, q, r, s), [True, False])


def test_an_arc_inverted_in_an_earlier_record_only_is_remembered(topology):
    """Two records of three instances: the first inverted, then back at rest; the second at rest
    throughout; the third stretched by 20 %, then non-finite. Each instance's checks are its
    own."""
    shape = first_arc_inverted(topology)
    rest = topology.rest_positions
    stretched = 1.2 * rest
    records = np.stack([np.stack([shape, rest, stretched]),
                        np.stack([rest, rest, np.full_like(rest, np.nan)])])
    checks = metrics.shape_checks(records, topology)
    assert checks["arc_inverted"].tolist() == [True, False, False]
    assert checks["arc_inverted_final"].tolist() == [False, False, False]
    assert checks["finite"].tolist() == [True, True, False]
    assert checks["max_strain_final"].iloc[0] < 1e-12
    assert checks["max_strain"].iloc[2] == pytest.approx(0.2, rel=1e-9)
