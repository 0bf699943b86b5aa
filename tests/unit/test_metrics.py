"""taichi_star.metrics on hand-made cases: shape checks (limb crossing, arc inversion,
strain, failed records) and the segment-crossing test they rest on; speeds, cycle-window
speeds and the heading against hand-worked values."""

import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from taichi_star import StarParams
from taichi_star import metrics
from taichi_star.geometry import build_topology, discrete_curvature


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


# ------------------------------------------------------------------ batches, limb segments, arcs


def _polar(radius, degrees):
    angle = np.radians(degrees)
    return radius * np.array([np.cos(angle), np.sin(angle)])


def _limb0_turned(topology, degrees):
    """The rest shape with limb 0 turned rigidly about its joint (edge lengths kept)."""
    shape = topology.rest_positions.copy()
    limb = topology.limbs[0]
    joint = shape[limb[0]]
    angle = np.radians(degrees)
    turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    shape[limb[1:]] = joint + (shape[limb[1:]] - joint) @ turn.T
    return shape


def _limb0_hooked_around_limb1(topology):
    """The rest shape with limb 0 (at -22.5°) hooked around limb 1's tip (limb 1 at 22.5°, tip
    radius 52 mm): out to 1.3x the tip radius, across limb 1's ray beyond its tip, and back in
    to 0.8x the tip radius at 35°, between limbs 1 and 2. No segment crosses limb 1, but the
    chord from limb 0's joint to its tip does."""
    shape = topology.rest_positions.copy()
    tip = StarParams().tip_radius
    shape[topology.limbs[0, 1:]] = [_polar(0.03, -20), _polar(1.3 * tip, -15),
                                    _polar(1.3 * tip, 10), _polar(1.3 * tip, 30),
                                    _polar(tip, 35), _polar(0.8 * tip, 35)]
    return shape


def test_limb_crossing_tests_each_limb_segment_not_chords_from_the_joint(topology):
    """Guards the limb-segment slicing of `limbs_cross` (consecutive nodes, not every node
    against the joint): a limb hooked around its neighbour's tip crosses nothing, although the
    chord from its joint to its tip cuts the neighbour; checked against the exact orientation
    rule on every pair of segments of limb 0 and another limb."""
    shape = _limb0_hooked_around_limb1(topology)
    limb0 = topology.limbs[0]
    segments0 = list(zip(limb0[:-1], limb0[1:]))
    for other in topology.limbs[1:]:
        for a, b in segments0:
            for c, d in zip(other[:-1], other[1:]):
                assert not _crossing_by_orientations(shape[a], shape[b], shape[c], shape[d])
    limb1 = topology.limbs[1]
    assert _crossing_by_orientations(shape[limb0[0]], shape[limb0[-1]],
                                     shape[limb1[0]], shape[limb1[-1]])  # the chord does cut
    assert not metrics.limbs_cross(shape, topology)


def test_limb_crossing_is_judged_per_instance_of_a_batch(topology):
    """Guards the reduction axes of `limbs_cross` (over limb pairs and segments only, not the
    batch): in a (2, 3) stack of shapes only the ones with limb 0 turned by 100° about its
    joint, through limb 1, cross."""
    rest = topology.rest_positions
    crossed = _limb0_turned(topology, 100.0)
    hooked = _limb0_hooked_around_limb1(topology)
    limb0, limb1 = topology.limbs[0], topology.limbs[1]
    # the turned limb cuts a segment of limb 1 (exact orientation rule)
    assert any(_crossing_by_orientations(crossed[a], crossed[b], crossed[c], crossed[d])
               for a, b in zip(limb0[:-1], limb0[1:]) for c, d in zip(limb1[:-1], limb1[1:]))
    stack = np.stack([np.stack([rest, crossed, hooked]), np.stack([crossed, rest, rest])])
    np.testing.assert_array_equal(metrics.limbs_cross(stack, topology),
                                  [[False, True, False], [True, False, False]])


def _with_zero_length_segment(shape, topology):
    """shape with limb 5's tip moved onto the node before it: a segment of zero length, which
    sends every limb pair of the shape to the exact test (`metrics.ORDINARY_SCALE`)."""
    shape = shape.copy()
    shape[topology.limbs[5, -1]] = shape[topology.limbs[5, -2]]
    return shape


@pytest.mark.parametrize("crossing_slice", [1, 2, 5, metrics.CROSSING_SLICE])
def test_limb_pairs_sliced_for_the_cache_are_judged_as_each_shape_alone(topology, monkeypatch,
                                                                         crossing_slice):
    """`limbs_cross` gives its exact test the limb pairs whose boxes come close in slices of
    CROSSING_SLICE pairs: with slices that cut one shape's pairs apart (28 for a shape with a
    zero-length segment, one for the turned or the hooked limb) and slices that join several
    shapes' pairs, and with two leading axes, each shape is judged as it is alone."""
    monkeypatch.setattr(metrics, "CROSSING_SLICE", crossing_slice)
    rest, crossed = topology.rest_positions, _limb0_turned(topology, 100.0)
    hooked = _limb0_hooked_around_limb1(topology)
    shapes = np.stack([crossed, hooked, rest, _with_zero_length_segment(crossed, topology),
                       _with_zero_length_segment(rest, topology), hooked, crossed, rest,
                       crossed, hooked])
    is_crossed = [True, False, False, True, False, False, True, False, True, False]
    assert [bool(metrics.limbs_cross(shape, topology)) for shape in shapes] == is_crossed
    np.testing.assert_array_equal(metrics.limbs_cross(shapes, topology), is_crossed)
    np.testing.assert_array_equal(metrics.limbs_cross(shapes.reshape(2, 5, -1, 2), topology),
                                  np.reshape(is_crossed, (2, 5)))


# ------------------------------------------------- the bounding-box prefilter of limbs_cross

GRID = 2.0 ** -9
"""1.95 mm: coordinates on this grid, and their differences, are exact in binary."""


def _limbs_0_and_1_set(topology, limb0, limb1):
    """The rest shape with the nodes of limbs 0 and 1 (at -22.5° and 22.5°) replaced by limb0
    and limb1 ((L+1, 2) m each); the other limbs are far from x > 20 mm, |y| < 15 mm."""
    shape = topology.rest_positions.copy()
    shape[topology.limbs[0]] = limb0
    shape[topology.limbs[1]] = limb1
    return shape


def _boxes_apart(shape, topology, a, b):
    """`_limb_boxes_apart` of limbs a < b of one shape."""
    first, second = np.triu_indices(len(topology.limbs), k=1)
    pair = np.flatnonzero((first == a) & (second == b))
    return bool(metrics._limb_boxes_apart(shape[None, topology.limbs], first, second)[0, pair])


def _grid_limb(x, y):
    """(L+1, 2) nodes at x, y (in GRID units; scalars or L+1 values)."""
    x, y = np.broadcast_arrays(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return GRID * np.stack([x, y], axis=-1)


@pytest.mark.parametrize("limb1_y, crosses", [
    # limb 1 up the edge x = 17 from y = 0.5: it overlaps limb 0's end segment (y in [0, 1])
    # along that edge by 0.5 GRID, a collinear crossing
    (0.5 + np.arange(7), True),
    # from y = 1, limb 0's tip: collinear, touching end to end, no crossing
    (1.0 + np.arange(7), False),
    # from y = 2: the boxes overlap nowhere (a gap of one GRID)
    (2.0 + np.arange(7), False),
])
def test_limbs_whose_boxes_touch_along_an_edge_take_the_exact_test(topology, limb1_y, crosses):
    """Guards the prefilter's boundary (`metrics._limb_boxes_apart`): two boxes that share only
    an edge, with zero overlap, can hold crossing limbs (collinear along that edge), so touching
    boxes go to the exact test; a strict comparison would drop the first case. Limb 0 runs along
    y = 0 to x = 17 GRID and turns up to (17, 1); limb 1 runs up the line x = 17 GRID, the edge
    of limb 0's box, from limb1_y[0]."""
    limb0 = _grid_limb([12, 13, 14, 15, 16, 17, 17], [0, 0, 0, 0, 0, 0, 1])
    shape = _limbs_0_and_1_set(topology, limb0, _grid_limb(17, limb1_y))
    touching = limb1_y[0] <= 1.0
    assert _boxes_apart(shape, topology, 0, 1) == (not touching)
    assert bool(metrics.limbs_cross(shape, topology)) == crosses
    assert bool(reference_limbs_cross(shape, topology)) == crosses


@pytest.mark.parametrize("limb1_x, crosses", [
    (18.0, False),  # a corner: limb 1 starts at limb 0's tip (18, 0), touching, no crossing
    (15.5, True),   # through limb 0's segment between x = 15 and 16: a proper crossing
])
def test_limbs_whose_boxes_touch_at_a_corner_or_overlap(topology, limb1_x, crosses):
    """Guards the prefilter's boundary: limb 0 along y = 0 from x = 12 to 18 GRID, limb 1 up the
    line x = limb1_x from y = 0 (at the corner of limb 0's box: the limbs touch at an end) or
    from y = -0.5 (the boxes overlap, the limbs cross); both go to the exact test."""
    limb0 = _grid_limb(12 + np.arange(7), 0)
    limb1 = _grid_limb(limb1_x, np.arange(7) - (0.5 if crosses else 0.0))
    shape = _limbs_0_and_1_set(topology, limb0, limb1)
    assert not _boxes_apart(shape, topology, 0, 1)
    assert bool(metrics.limbs_cross(shape, topology)) == crosses
    assert bool(reference_limbs_cross(shape, topology)) == crosses


def test_a_crossing_found_by_rounding_between_apart_boxes_is_kept(topology):
    """Guards `metrics.BOX_MARGIN`: limb 1 continues limb 0's line (turned by 0.2532 rad) past
    its tip, kinked by 4.14e-9 rad, just above PARALLEL_TOLERANCE, and 6.2e-12 m beyond it, so
    the limbs' boxes are 6.0e-12 m apart and the lines meet outside both limbs. The intersection
    parameters of so shallow a pair err by ~1e-7, and `segments_cross` finds a crossing: the
    prefilter must keep what it finds, so its margin exceeds any gap that rounding bridges."""
    phi, kink, gap = 0.2532434757273788, 4.1377454563537715e-09, 6.234699463676469e-12
    segment = 0.0025
    turn = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    direction = np.array([np.cos(kink), np.sin(kink)])
    # limb 1's line crosses y = 0 at gap / 2 beyond limb 0's tip, and starts gap / 2 further on
    start = np.array([0.035 + gap / 2, 0.0]) + (gap / 2) * direction
    limb0 = [turn @ np.array([0.035 - (6 - k) * segment, 0.0]) for k in range(7)]
    limb1 = [turn @ (start + k * segment * direction) for k in range(7)]
    shape = _limbs_0_and_1_set(topology, limb0, limb1)
    box0, box1 = shape[topology.limbs[0]], shape[topology.limbs[1]]
    assert (box1.min(axis=0) > box0.max(axis=0)).all()          # apart in both x and y
    assert (box1.min(axis=0) - box0.max(axis=0) < 1e-11).all()
    assert reference_limbs_cross(shape, topology)                # by rounding
    assert not _boxes_apart(shape, topology, 0, 1)
    assert metrics.limbs_cross(shape, topology)


FRESH_RUN = "TAICHI_STAR_TEST_FRESH_INTERPRETER"
"""Set in the fresh interpreter's environment, so that it never starts another."""


def subnormals_flushed() -> bool:
    """Whether this process flushes subnormal results to zero: `ti.init` sets the CPU's
    flush-to-zero mode for the whole process, NumPy included (measured: 1e-160² is 1e-320
    before it and 0.0 after it)."""
    tiny = np.array([1e-160])
    return bool((tiny * tiny)[0] == 0.0)


def test_shapes_too_small_for_the_margin_take_the_exact_test(topology, monkeypatch):
    """Guards `metrics.ORDINARY_SCALE`: in random stars shrunk 1e160-fold the products of
    `segments_cross` are subnormal (~1e-320), rounding noise, and it finds crossings between
    limbs whose boxes lie far more than BOX_MARGIN apart; every limb pair of such a shape takes
    the exact test, so `limbs_cross` still gives the brute force's result. Where Taichi has run
    in this process the products flush to zero and that noise never appears, so the test then
    runs itself again in a fresh interpreter (where it must pass as well), whatever the
    order the suite's files run in."""
    if subnormals_flushed():
        assert FRESH_RUN not in os.environ, "a fresh interpreter flushes subnormals too"
        name = "test_shapes_too_small_for_the_margin_take_the_exact_test"
        fresh = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-o",
             "addopts=--import-mode=importlib", f"{__file__}::{name}"],
            capture_output=True, text=True, cwd=Path(__file__).resolve().parents[2],
            env={**os.environ, FRESH_RUN: "1"})
        assert fresh.returncode == 0, fresh.stdout[-3000:] + fresh.stderr[-3000:]
        assert "1 passed" in fresh.stdout
        return
    rng = np.random.default_rng(1)
    shapes = random_stars(topology, rng, 400) * 1e-160
    first, second = np.triu_indices(len(topology.limbs), k=1)
    points = shapes[:, topology.limbs]
    with np.errstate(all="ignore"):
        pairs = reference_limb_pairs_cross(shapes, topology)
        np.testing.assert_array_equal(metrics.limbs_cross(shapes, topology), pairs.any(axis=-1))
        assert not (metrics._limb_boxes_apart(points, first, second) & pairs).any()
        monkeypatch.setattr(metrics, "ORDINARY_SCALE", (0.0, np.inf))
        assert (metrics._limb_boxes_apart(points, first, second) & pairs).any()


# ------------------------------------------- the fast shape checks against the reference code


def reference_limb_pairs_cross(positions, topology):
    """(S, N, 2) -> (S, pairs) bool: every segment of limb first[k] against every segment of
    limb second[k] (`np.triu_indices(8, k=1)`), brute force."""
    first, second = np.triu_indices(len(topology.limbs), k=1)
    points = positions[:, topology.limbs, :]              # (S, 8, L+1, 2)
    start, end = points[..., :-1, :], points[..., 1:, :]
    hit = metrics.segments_cross(start[:, first, :, None, :], end[:, first, :, None, :],
                                   start[:, second, None, :, :], end[:, second, None, :, :])
    return hit.any(axis=(-2, -1))


def reference_limbs_cross(positions, topology):
    """positions (..., N, 2) -> (...) bool: `metrics.limbs_cross` before the prefilter."""
    positions = np.asarray(positions)
    shapes = positions.reshape(-1, *positions.shape[-2:])
    return reference_limb_pairs_cross(shapes, topology).any(axis=-1).reshape(positions.shape[:-2])


def reference_arc_mean_curvature(positions, topology):
    """`metrics.arc_mean_curvature` before its speed-up, on `geometry.discrete_curvature`."""
    arcs = topology.arcs
    rest = topology.rest_positions[arcs]
    edge = np.linalg.norm(np.diff(rest, axis=1), axis=-1)
    voronoi = 0.5 * (edge[:, :-1] + edge[:, 1:])
    points = positions[..., arcs, :]
    kappa = discrete_curvature(points[..., :-2, :], points[..., 1:-1, :], points[..., 2:, :],
                               voronoi)
    return (kappa * voronoi).sum(-1) / voronoi.sum(-1)


def reference_arcs_inverted(positions, topology):
    rest = np.sign(reference_arc_mean_curvature(topology.rest_positions, topology))
    return (~(reference_arc_mean_curvature(positions, topology) * rest > 0)).any(axis=-1)


def reference_edge_lengths(positions, topology):
    edges = topology.edges
    return np.linalg.norm(positions[..., edges[:, 1], :] - positions[..., edges[:, 0], :],
                          axis=-1)


def reference_edge_strain(positions, topology, rest_positions=None):
    rest = (topology.rest_length if rest_positions is None
            else reference_edge_lengths(rest_positions, topology))
    return reference_edge_lengths(positions, topology) / rest - 1.0


def reference_shape_checks(shapes, topology, rest_positions=None):
    """`metrics.shape_checks` before its speed-up: every record, then the final one again."""
    shapes = np.asarray(shapes, dtype=np.float64)
    batch = shapes.shape[1]
    finite = np.isfinite(shapes).all(axis=(0, 2, 3))
    strain_max = np.full(batch, -np.inf)
    cross_any = np.zeros(batch, dtype=bool)
    inverted_any = np.zeros(batch, dtype=bool)
    for record in shapes:
        valid = np.isfinite(record).all(axis=(1, 2))
        strain = np.abs(reference_edge_strain(record, topology, rest_positions)).max(axis=-1)
        strain_max = np.where(valid, np.fmax(strain_max, strain), strain_max)
        cross_any |= reference_limbs_cross(record, topology) & valid
        inverted_any |= reference_arcs_inverted(record, topology) & valid
    final = shapes[-1]
    final_valid = np.isfinite(final).all(axis=(1, 2))
    table = pd.DataFrame({
        "max_strain": np.where(np.isfinite(strain_max), strain_max, np.nan),
        "max_strain_final": np.abs(reference_edge_strain(final, topology,
                                                         rest_positions)).max(axis=-1),
        "limbs_cross": cross_any,
        "limbs_cross_final": reference_limbs_cross(final, topology) & final_valid,
        "arc_inverted": inverted_any,
        "arc_inverted_final": reference_arcs_inverted(final, topology) & final_valid,
        "finite": finite,
    })
    table["sane"] = (finite & ~table["limbs_cross"] & ~table["arc_inverted"]
                     & (table["max_strain"] <= metrics.STRAIN_LIMIT))
    return table


def assert_bitwise_equal(actual, expected):
    """Equal shapes, dtypes and values, floats to the last bit (NaN where NaN, and 0.0 is not
    -0.0)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape and actual.dtype == expected.dtype
    if actual.dtype.kind == "f":
        assert np.array_equal(actual, expected, equal_nan=True)
        numbers = ~np.isnan(expected)
        assert np.array_equal(actual[numbers].view(np.uint64), expected[numbers].view(np.uint64))
    else:
        assert np.array_equal(actual, expected)


def assert_same_table(actual, expected):
    assert list(actual.columns) == list(expected.columns)
    for column in expected.columns:
        assert_bitwise_equal(actual[column].to_numpy(), expected[column].to_numpy())


def _straight_limb(shape, topology, limb):
    """shape's limb made straight: its nodes evenly from its joint to its tip."""
    nodes = topology.limbs[limb]
    fraction = np.linspace(0.0, 1.0, len(nodes))[:, None]
    shape[nodes] = shape[nodes[0]] + fraction * (shape[nodes[-1]] - shape[nodes[0]])


def random_stars(topology, rng, count):
    """count (N, 2) shapes m of the star, each the rest shape with noise of 10 µm, 1 mm or 4 mm
    (the larger crumple the limbs into each other's boxes) and one of: a limb turned about its
    joint (through its neighbours), a limb laid collinear on another, overlapping it or end to
    end, opposite limbs point-symmetric (collinear), a limb's tip on a node or a segment of
    another limb (touching), one limb's box clamped to touch another's along an edge, a NaN or
    infinite node or all NaN, the whole shape scaled to 1e-150 or 1e150 times its size or moved
    1 km, a zero-length segment; or nothing more."""
    rest = topology.rest_positions
    limbs = topology.limbs
    shapes = []
    for _ in range(count):
        shape = rest + rng.normal(0.0, rng.choice([1e-5, 1e-3, 4e-3]), rest.shape)
        a, b = rng.choice(len(limbs), 2, replace=False)
        case = rng.integers(10)
        if case == 0:
            angle = np.radians(rng.uniform(-180.0, 180.0))
            turn = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
            joint = shape[limbs[a, 0]]
            shape[limbs[a]] = joint + (shape[limbs[a]] - joint) @ turn.T
        elif case == 1:
            _straight_limb(shape, topology, a)
            along = shape[limbs[a, -1]] - shape[limbs[a, 0]]
            shift = rng.choice([rng.uniform(-1.5, 1.5), 1.0, -1.0])
            shape[limbs[b]] = shape[limbs[a]] + shift * along
        elif case == 2:
            shape[limbs[4:]] = -shape[limbs[:4]]
        elif case == 3:
            node = rng.integers(limbs.shape[1] - 1)
            on = shape[limbs[b, node]]
            if rng.random() < 0.5:
                on = 0.5 * (on + shape[limbs[b, node + 1]])
            shape[limbs[a, -1]] = on
        elif case == 4:
            axis = rng.integers(2)
            edge = shape[limbs[a], axis].max()
            shape[limbs[b], axis] = np.maximum(shape[limbs[b], axis], edge)
        elif case == 5:
            shape[rng.integers(len(shape)), rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
        elif case == 6:
            shape[:] = np.nan
        elif case == 7:
            shape = shape * rng.choice([1e-150, 1e150]) if rng.random() < 0.5 else shape + 1e3
        elif case == 8:
            shape[limbs[a, -1]] = shape[limbs[a, -2]]
        shapes.append(shape)
    return np.stack(shapes)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_limb_crossing_equals_the_brute_force_reference(topology, monkeypatch, seed):
    """`limbs_cross` (the bounding-box prefilter, then the exact test on the pairs it keeps, in
    slices) gives exactly the brute-force test of every segment pair on random stars
    (`random_stars`: crossing, collinear, touching, non-finite and extreme shapes), in one call
    with slices of 3 limb pairs and the default; the prefilter never drops a pair that the
    brute force finds crossing; the other shape checks' parts equal their references bitwise."""
    rng = np.random.default_rng(seed)
    shapes = random_stars(topology, rng, 400)
    with np.errstate(all="ignore"):
        pairs = reference_limb_pairs_cross(shapes, topology)
        expected = pairs.any(axis=-1)
        first, second = np.triu_indices(len(topology.limbs), k=1)
        apart = metrics._limb_boxes_apart(shapes[:, topology.limbs], first, second)
        assert not (apart & pairs).any()
        assert 0.05 < expected.mean() < 0.5 and (~apart).any(axis=-1).mean() < 1.0
        np.testing.assert_array_equal(metrics.limbs_cross(shapes, topology), expected)
        monkeypatch.setattr(metrics, "CROSSING_SLICE", 3)
        np.testing.assert_array_equal(metrics.limbs_cross(shapes.reshape(20, 20, -1, 2), topology),
                                      expected.reshape(20, 20))
        # segments_cross's only change: its lengths by metrics._norm, bitwise NumPy's norm
        vectors = np.concatenate([shapes.reshape(-1, 2), rng.normal(size=(1000, 2)) * np.exp(
            rng.uniform(-300, 300, size=(1000, 1)))])
        assert_bitwise_equal(metrics._norm(vectors[:, 0], vectors[:, 1]),
                             np.linalg.norm(vectors, axis=-1))
        for stack in (shapes, shapes.reshape(20, 20, -1, 2), shapes[:1], shapes[0]):
            assert_bitwise_equal(metrics.arc_mean_curvature(stack, topology),
                                 reference_arc_mean_curvature(stack, topology))
        assert_bitwise_equal(metrics.arcs_inverted(shapes, topology),
                             reference_arcs_inverted(shapes, topology))
        assert_bitwise_equal(metrics.edge_lengths(shapes, topology),
                             reference_edge_lengths(shapes, topology))
        own_rest = shapes[::-1]
        assert_bitwise_equal(metrics.edge_strain(shapes, topology, own_rest),
                             reference_edge_strain(shapes, topology, own_rest))


@pytest.mark.parametrize("batch, shape_slice", [(150, 149), (129, 64), (7, 3), (2, 2), (1, 64)])
def test_shape_checks_sums_the_arcs_of_every_slice_as_of_the_whole_record(topology, monkeypatch,
                                                                          batch, shape_slice):
    """Guards the slice bounds of `shape_checks`: NumPy sums each arc's curvatures in an order
    that follows their memory layout, another for one shape than for a batch, so a slice of a
    lone instance would give its mean curvatures other last bits than the whole record does
    (and a mean that is zero up to round-off another sign). The means computed on the slices
    equal those of the whole record, bitwise, with SHAPE_SLICE leaving one instance over."""
    monkeypatch.setattr(metrics, "SHAPE_SLICE", shape_slice)
    arc_mean_curvature, means = metrics.arc_mean_curvature, []

    def recorded(positions, topology):
        mean = arc_mean_curvature(positions, topology)
        if positions.ndim == 3:  # not the rest shape
            means.append(mean)
        return mean

    monkeypatch.setattr(metrics, "arc_mean_curvature", recorded)
    rest = topology.rest_positions
    record = rest + np.random.default_rng(7).normal(0.0, 1e-3, (batch,) + rest.shape)
    metrics.shape_checks(record[None], topology)
    assert_bitwise_equal(np.concatenate(means), reference_arc_mean_curvature(record, topology))


@pytest.mark.parametrize("seed, n_records, own_rest, shape_slice", [
    (0, 1, True, metrics.SHAPE_SLICE), (1, 1, False, 7), (2, 3, True, 149), (3, 3, False, 2),
    (4, 2, True, 37),
])
def test_shape_checks_equal_the_reference_code(topology, monkeypatch, seed, n_records,
                                               own_rest, shape_slice):
    """`shape_checks` (instances in slices of SHAPE_SLICE, the final record's checks taken from
    the loop over records) gives exactly the table of the code it replaced, which checked every
    record and then the final one again: random stars (`random_stars`; the first 20 instances
    quiet, sane ones) in 1 to 3 records of 150 instances, some failing (NaN from a record on)
    or NaN in one earlier record only, five crossed in the final record but with a NaN node
    there, with one rest shape per instance (scaled 0.9 to 1.1 and jittered) or the
    topology's."""
    monkeypatch.setattr(metrics, "SHAPE_SLICE", shape_slice)
    rng = np.random.default_rng(seed)
    batch = 150
    shapes = random_stars(topology, rng, n_records * batch).reshape(n_records, batch, -1, 2)
    rest = topology.rest_positions
    shapes[:, :20] = rest + rng.normal(0.0, 1e-5, (n_records, 20) + rest.shape)  # sane ones
    failed_from = rng.integers(0, 3 * n_records, batch)   # mostly never
    for record in range(n_records):
        shapes[record, failed_from <= record] = np.nan
    shapes[0, rng.choice(batch, 5)] = np.nan
    # crossing limbs in a record that is skipped, as one node (of limb 4) is NaN
    shapes[-1, 20:25] = _limb0_turned(topology, 100.0)
    shapes[-1, 20:25, topology.limbs[4, 3], 1] = np.nan
    rest_positions = (rng.uniform(0.9, 1.1, (batch, 1, 1)) * rest
                      + rng.normal(0.0, 1e-4, (batch,) + rest.shape)) if own_rest else None
    with np.errstate(all="ignore"):
        expected = reference_shape_checks(shapes, topology, rest_positions)
        assert_same_table(metrics.shape_checks(shapes, topology, rest_positions), expected)
    assert expected["limbs_cross_final"].any() and expected["arc_inverted_final"].any()
    assert expected["sane"].any() and not expected["finite"].all()


def _circumcentre(a, b, c):
    """Centre of the circle through three points (2-D)."""
    d = 2.0 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
    ux = ((a @ a) * (b[1] - c[1]) + (b @ b) * (c[1] - a[1]) + (c @ c) * (a[1] - b[1])) / d
    uy = ((a @ a) * (c[0] - b[0]) + (b @ b) * (a[0] - c[0]) + (c @ c) * (b[0] - a[0])) / d
    return np.array([ux, uy])


def test_arc_mean_curvature_weights_by_each_nodes_own_rest_voronoi_length(topology):
    """Guards the rest Voronoi lengths ½(Δl_{i-1} + Δl_i) of `arc_mean_curvature`: a topology
    whose arc 0 has its nodes unevenly spaced on its rest circle (edge angles growing 1:18 from
    J_0 to J_1) still gives that arc the circle's curvature 1/ρ as its mean; a weighting that
    mixed up the edges would be off by tens of per cent."""
    import dataclasses

    rest = topology.rest_positions
    arc = topology.arcs[0]
    centre = _circumcentre(rest[arc[0]], rest[arc[len(arc) // 2]], rest[arc[-1]])
    radius = np.linalg.norm(rest[arc[0]] - centre)
    assert radius == pytest.approx(1.0 / StarParams().actuator_profile.rest_curvature, rel=1e-9)
    start, end = (np.arctan2(*(rest[arc[k]] - centre)[::-1]) for k in (0, -1))
    steps = np.arange(1, len(arc))                      # edge k subtends an angle ∝ k + 1
    fractions = np.cumsum(steps)[:-1] / steps.sum()
    sweep = (end - start + np.pi) % (2 * np.pi) - np.pi  # the minor arc, through the bulge
    angles = start + sweep * fractions
    uneven = rest.copy()
    uneven[arc[1:-1]] = centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    edges = np.linalg.norm(np.diff(uneven[arc], axis=0), axis=1)
    assert edges[-1] > 15 * edges[0]
    uneven_topology = dataclasses.replace(topology, rest_positions=uneven)
    mean = metrics.arc_mean_curvature(uneven, uneven_topology)
    # On a circle, κ_i·Δl_i = 2 tan(θ_i/2) with θ_i the turning at node i, and the chords are
    # shorter than their arcs by φ²/24: the mean overestimates 1/ρ by about φ²/12, 0.6 % for
    # the largest edge angle φ = 0.26 rad here. Walking from J_0 to J_1 (counter-clockwise about
    # the hub) the arc bulges towards the hub, a clockwise turn: negative.
    assert mean[0] == pytest.approx(-1.0 / radius, rel=1e-2)
    # the other arcs keep their even rest spacing and curvature
    np.testing.assert_allclose(mean[1:], metrics.arc_mean_curvature(rest, topology)[1:],
                               rtol=1e-12)


def _arc0_on_circle(topology, curvature):
    """The rest shape with arc 0's interior nodes evenly on the circle of signed `curvature`
    (1/m, sign as `arc_mean_curvature`: negative bulges towards the hub like the rest shape)
    through J_0 and J_1. J_0 and J_1 lie symmetric about the x axis."""
    shape = topology.rest_positions.copy()
    arc = topology.arcs[0]
    a, b = shape[arc[0]], shape[arc[-1]]
    half_chord = 0.5 * (b[1] - a[1])
    radius = 1.0 / abs(curvature)
    # centre on the far side of the chord from the bulge: outside (+x) for a bulge to the hub
    offset = np.sqrt(radius ** 2 - half_chord ** 2) * (1.0 if curvature < 0 else -1.0)
    centre = np.array([a[0] + offset, 0.0])
    span = np.arcsin(half_chord / radius)
    angles = (np.pi + np.linspace(span, -span, len(arc))[1:-1] if curvature < 0
              else np.linspace(-span, span, len(arc))[1:-1])
    shape[arc[1:-1]] = centre + radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    return shape


def test_a_nearly_straight_arc_bulging_the_rest_way_is_not_inverted(topology):
    """Guards the sign test of `arcs_inverted` (the sign of the mean curvature, not its size):
    arc 0 flattened to 0.5 1/m (radius 2 m, 200x flatter than at rest) but still bulging
    towards the hub is not inverted; the same flat arc bulging outwards is."""
    same, opposite = _arc0_on_circle(topology, -0.5), _arc0_on_circle(topology, 0.5)
    rest = topology.rest_positions
    arc = topology.arcs[0]
    chord = np.linalg.norm(rest[arc[-1]] - rest[arc[0]])
    rest_length = np.linalg.norm(np.diff(rest[arc], axis=0), axis=1).sum()
    # the mean is the arc's turning, about 0.5 1/m x its chord, over its rest length (the same
    # share of the ends' half-edges drops out of both); chord against arc of the flat circle
    # and the rest circle's discretisation (~φ²/12 at φ = 0.14 rad) stay well within 1 %
    expected = 0.5 * chord / rest_length
    assert expected < 1.0
    assert metrics.arc_mean_curvature(same, topology)[0] == pytest.approx(-expected, rel=1e-2)
    assert metrics.arc_mean_curvature(opposite, topology)[0] == pytest.approx(expected, rel=1e-2)
    assert not metrics.arcs_inverted(same, topology)
    assert metrics.arcs_inverted(opposite, topology)


def test_arc_inversion_is_judged_per_shape_for_any_leading_axes(topology):
    """Guards the reduction axis of `arcs_inverted` (over the eight arcs only): a single (N, 2)
    shape gives one flag, and a (2, 3) stack gives each shape's own flag."""
    rest = topology.rest_positions
    inverted, flat = first_arc_inverted(topology), _arc0_on_circle(topology, -0.5)
    assert metrics.arcs_inverted(inverted, topology) and not metrics.arcs_inverted(rest, topology)
    stack = np.stack([np.stack([rest, inverted, flat]), np.stack([inverted, flat, rest])])
    np.testing.assert_array_equal(metrics.arcs_inverted(stack, topology),
                                  [[False, True, False], [True, False, False]])


# ------------------------------------------------------------------ shape_checks over a batch


def test_a_non_finite_instance_does_not_hide_the_other_instances_records(topology):
    """Guards the per-instance validity of each record and of the final shape in
    `shape_checks`: two records of three instances, the second instance non-finite throughout.
    The first is stretched by 30 % then has limb 0 turned through limb 1; the third has limb 0
    turned through limb 1, then arc 0 inverted. Their strain, crossing and inversion are found
    although another instance of the same records is NaN; the NaN instance has no strain
    (NaN) and is not sane."""
    rest = topology.rest_positions
    crossed = _limb0_turned(topology, 100.0)
    failed = np.full_like(rest, np.nan)
    records = np.stack([np.stack([1.3 * rest, failed, crossed]),
                        np.stack([crossed, failed, first_arc_inverted(topology)])])
    checks = metrics.shape_checks(records, topology)
    # 1.3 x every coordinate: every edge 1.3 x longer up to round-off; the turned limb and the
    # reflected arc keep their lengths up to round-off
    assert checks["max_strain"].iloc[0] == pytest.approx(0.3, rel=1e-9)
    assert np.isnan(checks["max_strain"].iloc[1])
    assert checks["max_strain"].iloc[2] < 1e-12
    assert checks["max_strain"].dtype == np.float64
    assert checks["max_strain_final"].iloc[0] < 1e-12
    assert checks["limbs_cross"].tolist() == [True, False, True]
    assert checks["limbs_cross_final"].tolist() == [True, False, False]
    assert checks["arc_inverted"].tolist() == [False, False, True]
    assert checks["arc_inverted_final"].tolist() == [False, False, True]
    assert checks["finite"].tolist() == [True, False, True]
    assert checks["sane"].tolist() == [False, False, False]


def test_final_strain_is_measured_against_each_instances_own_rest_shape():
    """Guards the rest-shape argument of the final-shape strain in `shape_checks`: two robots
    of different geometry, each blown up by 10 % from its own rest shape in the final record;
    max_strain_final is 0.1 for both (against the topology's default rest lengths the second,
    smaller robot would show its size difference too)."""
    own = np.stack([build_topology(StarParams()).rest_positions,
                    build_topology(StarParams(joint_radius=0.022, tip_radius=0.05)).rest_positions])
    topology = build_topology(StarParams())
    records = np.stack([own, 1.1 * own])
    checks = metrics.shape_checks(records, topology, own)
    # 1.1 x every coordinate: ε = 0.1 up to round-off
    np.testing.assert_allclose(checks["max_strain_final"], [0.1, 0.1], rtol=1e-9)
    np.testing.assert_allclose(checks["max_strain"], [0.1, 0.1], rtol=1e-9)
    assert checks["sane"].all()


def test_a_strain_exactly_at_the_limit_is_sane(topology):
    """Guards the boundary of `sane`: |ε| above STRAIN_LIMIT is not sane, so ε exactly at it
    is. Limb 0's last edge, made axis-parallel with binary-exact lengths in an instance's own
    rest shape (2⁻⁹ m) and in the shape (1.5 x 2⁻⁹ m), has ε = 0.5 exactly and every other edge
    ε = 0; one 2⁻²⁰ m (1 µm) longer is over the limit."""
    assert metrics.STRAIN_LIMIT == 0.5
    limb = topology.limbs[0]
    before_tip, tip = limb[-2], limb[-1]
    grid = 2.0 ** -20
    own_rest = topology.rest_positions.copy()
    own_rest[before_tip] = np.round(own_rest[before_tip] / grid) * grid
    length = 2.0 ** -9
    own_rest[tip] = own_rest[before_tip] + [length, 0.0]
    at_limit, over = own_rest.copy(), own_rest.copy()
    at_limit[tip] = own_rest[before_tip] + [1.5 * length, 0.0]
    over[tip] = own_rest[before_tip] + [1.5 * length + grid, 0.0]
    checks = metrics.shape_checks(np.stack([at_limit, over])[None], topology,
                                  np.stack([own_rest, own_rest]))
    assert checks["max_strain"].iloc[0] == 0.5 and checks["max_strain_final"].iloc[0] == 0.5
    assert checks["max_strain"].iloc[1] > 0.5
    assert not checks["limbs_cross"].any() and not checks["arc_inverted"].any()
    assert checks["sane"].tolist() == [True, False]


def test_single_precision_records_are_checked_in_double_precision(topology):
    """Guards the float64 conversion in `shape_checks`: f32 records (an f32 run's shapes) give
    exactly the table of the same values converted to f64 first (f32 arithmetic would move
    the strains by ~1e-7)."""
    rng = np.random.default_rng(3)
    rest = topology.rest_positions
    records = (rest + rng.normal(0.0, 2e-4, (2, 3) + rest.shape)).astype(np.float32)
    single = metrics.shape_checks(records, topology)
    double = metrics.shape_checks(records.astype(np.float64), topology)
    pd.testing.assert_frame_equal(single, double, check_exact=True)


def test_crossing_checks_run_under_strict_floating_point_error_settings(topology):
    """Guards the local np.errstate of `segments_cross`: parallel segments divide by zero
    (offset: x/0; collinear: 0/0) by design, so the crossing checks must not raise or warn
    under a caller's np.errstate(all="raise"); the rest shape's opposite limbs are collinear."""
    p, q = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    with np.errstate(all="raise"):
        assert not metrics.segments_cross(p, q, np.array([0.0, 1e-3]), np.array([1.0, 1e-3]))
        assert metrics.segments_cross(p, q, np.array([0.5, 0.0]), np.array([2.0, 0.0]))
        assert not metrics.limbs_cross(topology.rest_positions, topology)


# ----------------------------------------------------------------------------- errors, extrapolation

def test_speed_error_floor_boundary():
    floor = metrics.SPEED_ERROR_FLOOR_MM_S
    assert floor == 0.5  # the design's §3 metric
    assert metrics.speed_error(2.2, 2.0) == pytest.approx(0.1, rel=1e-12)
    # below the floor the error is absolute, in units of the floor; at the floor both agree
    assert metrics.speed_error(0.105, 0.1) == pytest.approx(0.005 / floor, rel=1e-9)
    assert metrics.speed_error(-0.2, 0.2) == pytest.approx(0.4 / floor, rel=1e-12)
    assert metrics.speed_error(0.6, 0.5) == pytest.approx(0.2, rel=1e-12)
    assert metrics.speed_error(-2.0, -1.0) == pytest.approx(1.0, rel=1e-12)  # |v_ref| scales
    assert metrics.speed_error([1.0, 3.0], 2.0).tolist() == [0.5, 0.5]
    assert metrics.speed_error(0.105, 0.1, floor_mm_s=0.0) == pytest.approx(0.05, rel=1e-9)
    assert np.isnan(metrics.speed_error(np.nan, 1.0))
    for bad in (-0.1, np.inf, np.nan):
        with pytest.raises(ValueError, match="floor_mm_s"):
            metrics.speed_error(1.0, 1.0, floor_mm_s=bad)


@pytest.mark.parametrize("order, refinement", [(1.0, 2.0), (2.0, 2.0), (1.5, 3.0)])
def test_richardson_is_exact_for_a_power_law(order, refinement):
    """v(h) = L + C h^p on h, h/r, h/r²: the observed order is p and the limit L (round-off)."""
    h = np.array([1.0, 1.0 / refinement, 1.0 / refinement ** 2])
    coarse, middle, fine = 3.0 + np.outer(h ** order, [2.0, -1.0])  # two quantities
    observed = metrics.observed_order(middle - coarse, fine - middle, refinement)
    assert observed == pytest.approx([order, order], rel=1e-12)
    limit = metrics.richardson_limit(middle, fine, observed, refinement)
    assert limit == pytest.approx([3.0, 3.0], rel=1e-12)


def test_observed_order_needs_monotone_changes():
    # changes of opposite sign (oscillation) or a zero change: no order, and no limit from it
    assert np.isnan(metrics.observed_order(0.1, -0.05))
    assert np.isnan(metrics.observed_order(0.0, 0.05))
    assert np.isnan(metrics.observed_order(0.1, 0.0))
    assert metrics.observed_order(-0.4, -0.1) == pytest.approx(2.0, rel=1e-12)
    assert np.isnan(metrics.richardson_limit(1.0, 1.1, np.nan))


@pytest.mark.parametrize("order, limit", [(-2.0, np.nan), (0.0, np.nan), (-1e-300, np.nan),
                                          (2.0, 1.04 + 0.04 / 3), (1e-9, None)])
def test_a_diverging_ladder_has_no_richardson_limit(order, limit):
    """Changes that grow (an observed order of −2) put the formula's "limit" below both levels
    of a rising ladder, 0.9867, and an order of 0 at infinity (an audit, 2026-12): NaN for an
    order that is not > 0; any positive order extrapolates, a tiny one far (1e-9: 1.04 + 0.04
    / (2^1e-9 − 1), 5.8e7)."""
    got = float(metrics.richardson_limit(1.0, 1.04, order))
    if limit is None:
        assert got == pytest.approx(1.04 + 0.04 / (2.0 ** 1e-9 - 1.0), rel=1e-6) and got > 5e7
    elif np.isnan(limit):
        assert np.isnan(got)
    else:
        assert got == pytest.approx(limit, rel=1e-15)
    np.testing.assert_array_equal(np.isnan(metrics.richardson_limit(
        [1.0, 1.0], [1.04, 1.04], [-2.0, 2.0])), [True, False])


@pytest.mark.parametrize("refinement", [1.0, 0.5, 0.0, -2.0, np.nan, np.inf, "2", 10**400])
def test_a_refinement_that_refines_nothing_is_refused(refinement):
    """A refinement of 1 gave inf and one of 0.5 a negative order: both helpers take only a
    finite number > 1."""
    for call in (lambda: metrics.observed_order(0.4, 0.1, refinement),
                 lambda: metrics.richardson_limit(1.0, 1.1, 2.0, refinement)):
        with pytest.raises(ValueError, match="^refinement must be a finite number > 1"):
            call()
    assert metrics.observed_order(0.9, 0.1, 3.0) == pytest.approx(2.0, rel=1e-12)


def test_shape_checks_need_at_least_one_record_of_instances(topology):
    n_nodes = len(topology.rest_positions)
    with pytest.raises(ValueError, match="at least one record"):
        metrics.shape_checks(np.zeros((0, 2, n_nodes, 2)), topology)
    with pytest.raises(ValueError, match=r"\(R, B, N, 2\)"):
        metrics.shape_checks(np.zeros((2, n_nodes, 2)), topology)
    one = metrics.shape_checks(topology.rest_positions[None, None], topology)  # the boundary: R = 1
    assert bool(one["sane"].iloc[0]) and one["max_strain"].iloc[0] == 0.0


# ----------------------------------------------------------------------------- speeds and heading

def test_swimming_metrics_of_hand_made_displacements():
    """A 3-4-5 displacement and one along -x: speed |d|/T, the signed speed the projection on
    the gait's forward direction (A1+A3: 45°; A5: -x), NaN where the bisectors cancel (A1+A5),
    the travel direction counter-clockwise from +x; each instance over its own duration."""
    displacement_m = np.array([[3e-3, 4e-3], [-3e-3, 0.0], [3e-3, 4e-3]])
    duration_s = np.array([2.0, 2.0, 0.5])
    got = metrics.swimming_metrics(displacement_m, duration_s, ["A1+A3", "A5", "A1+A5"])
    assert list(got) == list(metrics.SPEED_COLUMNS)
    # 1e-15: a product, a square root and a quotient of exact decimal inputs
    np.testing.assert_allclose(got["displacement_x_mm"], [3.0, -3.0, 3.0], rtol=1e-15)
    np.testing.assert_allclose(got["displacement_y_mm"], [4.0, 0.0, 4.0], rtol=1e-15)
    np.testing.assert_allclose(got["speed_mm_s"], [2.5, 1.5, 10.0], rtol=1e-15)
    np.testing.assert_allclose(got["signed_speed_mm_s"][:2], [7.0 / math.sqrt(2) / 2.0, 1.5],
                               rtol=1e-15)
    assert np.isnan(got["signed_speed_mm_s"][2])
    np.testing.assert_allclose(got["travel_direction_deg"],
                               [math.degrees(math.atan2(4.0, 3.0)), 180.0,
                                math.degrees(math.atan2(4.0, 3.0))], rtol=1e-15)


def _boundary_centroids(rows):
    """(B, 4, 2) centroids (m) at t = 0, T, 2T, 3T from rows of four (x, y) in mm, None where a
    boundary was not recorded."""
    return np.array([[(np.nan, np.nan) if point is None else point for point in row]
                     for row in rows], dtype=np.float64) * 1e-3


@pytest.mark.filterwarnings("error")  # a window of no cycle must not be a 0/0 of NumPy's
def test_cycle_window_speeds_span_first_cycle_to_the_last_recorded_boundary():
    """From cycle 1 on, over boundaries t = 0, T, 2T, 3T: a whole run spans two cycles, one
    whose last recorded boundary is 2T exactly one (the fewest: a speed), one ending at T none
    (NaN), as one that failed (no boundary) or whose boundary T is missing; each instance over
    its own period and forward direction (A1: +x, A1+A3: 45°, A1+A5: none)."""
    centroids = _boundary_centroids([
        [(0, 0), (1, 0), (3, 1), (6, 2)],          # A1, T = 2 s: (5, 2) mm over 4 s
        [(0, 0), (1, 1), (4, 5), None],            # A1+A3, T = 1 s: (3, 4) mm over 1 s
        [(0, 0), (2, 0), None, None],              # no whole cycle after cycle 1
        [(0, 0), (1, 0), (1, 3), (1, 6)],          # A1+A5, T = 2 s: (0, 6) mm over 4 s
        [None, None, None, None],                  # failed: nothing recorded
        [(0, 0), None, (1, 0), (2, 0)],            # the window's first boundary missing
    ])
    periods = np.array([2.0, 1.0, 2.0, 2.0, 2.0, 2.0])
    gaits = ["A1", "A1+A3", "A1", "A1+A5", "A1", "A1"]
    got = metrics.cycle_window_speeds(centroids, periods, gaits, first_cycle=1)
    # 1e-15 relative: a difference, a hypot and a quotient of small whole millimetres
    nan = np.nan
    np.testing.assert_allclose(got["steady_speed_mm_s"],
                               [math.hypot(5, 2) / 4, 5.0, nan, 1.5, nan, nan], rtol=1e-15)
    np.testing.assert_allclose(got["steady_signed_speed_mm_s"],
                               [5 / 4, 7 / math.sqrt(2), nan, nan, nan, nan], rtol=1e-15)
    # from cycle 0 the window starts at t = 0: the third instance has its one cycle
    from_start = metrics.cycle_window_speeds(centroids, periods, gaits, first_cycle=0)
    np.testing.assert_allclose(from_start["steady_speed_mm_s"][:3],
                               [math.hypot(6, 2) / 6, math.hypot(4, 5) / 2, 1.0], rtol=1e-15)
    # a window starting at the last boundary, or past every boundary, has no cycle
    for first_cycle in (3, 4):
        past = metrics.cycle_window_speeds(centroids, periods, gaits, first_cycle)
        assert np.isnan(past["steady_speed_mm_s"]).all()
        assert np.isnan(past["steady_signed_speed_mm_s"]).all()


def _turned(shape, angle_rad, about, shift):
    """shape (N, 2) turned by angle_rad counter-clockwise about the point `about`, then
    shifted by `shift` (a rotation matrix written out, not `metrics.rotate`)."""
    cos, sin = math.cos(angle_rad), math.sin(angle_rad)
    matrix = np.array([[cos, -sin], [sin, cos]])
    return (shape - about) @ matrix.T + about + shift


@pytest.mark.parametrize("degrees, expected", [
    (30.0, 30.0), (-75.0, -75.0), (179.0, 179.0), (190.0, -170.0), (-181.0, 179.0), (0.0, 0.0)])
def test_body_rotation_of_a_rigidly_turned_rest_shape_is_its_angle(topology, degrees, expected):
    """The rest shape turned about an off-centre point and moved: its heading is the turn,
    in (-180°, 180°] (a turn past ±180° comes back on the other side), whatever the move."""
    rest = topology.rest_positions
    shape = _turned(rest, math.radians(degrees), np.array([0.013, -0.021]), np.array([0.4, 0.7]))
    got = metrics.body_rotation(shape, rest, topology.joints)
    # 1e-12 rad: arctan2 of coordinates ~5 cm rounded at 1e-17 m, summed over eight joints
    assert math.degrees(float(got)) == pytest.approx(expected, abs=1e-12)
    stack = np.stack([rest, shape])    # leading axes: one heading per shape
    np.testing.assert_allclose(np.degrees(metrics.body_rotation(stack, rest, topology.joints)),
                               [0.0, expected], rtol=0, atol=1e-12)


@pytest.mark.parametrize("angle, wrapped", [
    (180.0, -180.0), (-180.0, -180.0), (179.5, 179.5), (-181.0, 179.0), (540.0, -180.0),
    (359.0, -1.0), (0.0, 0.0)])
def test_wrap_degrees_lands_in_minus_180_to_180_excluded(angle, wrapped):
    """[-180, 180): -180 itself stays, +180 and every odd multiple go to -180."""
    assert metrics.wrap_degrees(angle) == wrapped


@pytest.mark.parametrize("angle, wrapped", [
    (180.0, 180.0), (-180.0, 180.0), (179.5, 179.5), (-179.5, -179.5), (-181.0, 179.0),
    (540.0, 180.0), (-540.0, 180.0), (359.0, -1.0), (0.0, 0.0)])
def test_wrap_degrees_including_180_lands_in_minus_180_excluded_to_180(angle, wrapped):
    """(-180, 180] (the gaits table's convention): +180 stays, -180 and every odd multiple go
    to +180; elementwise on arrays too."""
    assert metrics.wrap_degrees(angle, include_180=True) == wrapped
    assert metrics.wrap_degrees([angle, 0.0], include_180=True).tolist() == [wrapped, 0.0]


def test_wrap_degrees_of_nan_or_infinity_is_nan():
    """NaN for NaN and ±inf, as documented, and without NumPy's "invalid value" warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for include_180 in (False, True):
            assert np.isnan(metrics.wrap_degrees([np.nan, np.inf, -np.inf],
                                                 include_180=include_180)).all()


def test_angles_a_rounding_past_half_a_turn_stay_in_their_range():
    """(x + 180) % 360 rounds to 360 for x a hair below -180: -180.00000000000003 wrapped to
    +180, outside [-180, 180); and a body turned by half a turn read -π by the sign of a zero,
    outside (-π, π] (an audit, 2026-12)."""
    assert metrics.wrap_degrees(-180.00000000000003) == -180.0
    assert metrics.wrap_degrees(-180.00000000000003, include_180=True) == 180.0
    rest = build_topology(StarParams(n_arc=6, n_limb=2))
    turned = metrics.rotate(rest.rest_positions, -math.pi)
    assert metrics.body_rotation(turned, rest.rest_positions, rest.joints) == math.pi
    assert metrics.body_rotation(rest.rest_positions, rest.rest_positions, rest.joints) == 0.0


@pytest.mark.parametrize("floor", [True, None, "0.5", -1.0, math.nan, 10**400])
def test_a_speed_errors_floor_is_a_number(floor):
    """A bool was taken as a floor of 1, None or text a TypeError: ValueError naming it."""
    with pytest.raises(ValueError, match="^floor_mm_s must be a finite number >= 0"):
        metrics.speed_error(1.0, 2.0, floor_mm_s=floor)
