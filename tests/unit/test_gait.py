"""Gaits as values: parsing and its errors, the actuator mask and bits, the forward direction,
the octagon's symmetries and the 29 symmetry classes, each checked against an independent
construction (combinatorics, rotation matrices) rather than against the module itself."""

import itertools
import math

import numpy as np
import pytest

from taichi_star.gait import Gait, actuator_direction, canonical_gait, symmetry_classes

ALL_ACTUATORS = "A1+A2+A3+A4+A5+A6+A7+A8"


def rotation(degrees):
    radians = math.radians(degrees)
    return np.array([[math.cos(radians), -math.sin(radians)],
                     [math.sin(radians), math.cos(radians)]])


def test_actuator_bisectors_are_unit_vectors_45_degrees_apart_from_plus_x():
    # 1e-15: a few roundings of cos/sin of a multiple of 45 degrees
    np.testing.assert_allclose(actuator_direction(1), [1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(actuator_direction(3), [0.0, 1.0], atol=1e-15)
    for number in range(1, 9):
        expected = rotation(45.0 * (number - 1)) @ np.array([1.0, 0.0])
        np.testing.assert_allclose(actuator_direction(number), expected, atol=1e-15)


@pytest.mark.parametrize("text,actuators,name", [
    ("A2+A1", (1, 2), "A1+A2"),
    (" a8 + A3 ", (3, 8), "A3+A8"),
    ("  None ", (), "none"),
    ("NONE", (), "none"),
    ("A5", (5,), "A5"),
])
def test_parse_accepts_any_order_case_and_spacing_and_names_canonically(text, actuators, name):
    gait = Gait.parse(text)
    assert gait.actuators == actuators
    assert gait.name == str(gait) == canonical_gait(text) == name
    assert Gait.parse(gait) is gait


@pytest.mark.parametrize("text,message", [
    ("A9", "unknown actuator 'A9'"), ("A0", "unknown actuator 'A0'"),
    ("A1+B2", "unknown actuator 'B2'"), ("A12", "unknown actuator 'A12'"),
    ("X1", "unknown actuator 'X1'"), ("AX", "unknown actuator 'AX'"),
    ("A1+", "unknown actuator ''"), ("A1+A1", "repeated"), ("a3+A3", "repeated"),
])
def test_parse_names_the_bad_text_and_the_allowed_form(text, message):
    with pytest.raises(ValueError, match=message) as error:
        Gait.parse(text)
    assert repr(text) in str(error.value) and '"A1".."A8"' in str(error.value)


def test_a_gait_that_is_not_text_is_refused_with_the_allowed_form():
    with pytest.raises(ValueError, match=r"gait must be a string \(allowed: .*got 3"):
        Gait.parse(3)


@pytest.mark.parametrize("actuators,message", [((0,), "numbers 1..8"), ((9,), "numbers 1..8"),
                                               ((2, 2), "must not repeat")])
def test_gait_built_from_numbers_is_validated(actuators, message):
    with pytest.raises(ValueError, match=message):
        Gait(actuators)


def test_gait_from_numbers_is_sorted_and_equal_to_the_parsed_one():
    assert Gait((8, 1, 3)).actuators == (1, 3, 8)
    assert Gait((8, 1, 3)) == Gait.parse("A3+A1+A8")
    assert Gait.parse("A1") == Gait((np.int64(1),))


def test_mask_and_bits_mark_exactly_the_fired_actuators():
    for size in range(0, 9):
        for actuators in itertools.combinations(range(1, 9), size):
            gait = Gait(actuators)
            expected = np.array([1 if m + 1 in actuators else 0 for m in range(8)])
            assert gait.mask.dtype == np.int32
            np.testing.assert_array_equal(gait.mask, expected)
            assert gait.bits == int("".join(map(str, expected[::-1])), 2)
            assert Gait.from_mask(expected.astype(bool)) == gait


def test_from_mask_refuses_a_mask_of_another_length_naming_the_shape():
    with pytest.raises(ValueError, match=r"shape \(8,\), got \(7,\)"):
        Gait.from_mask([1] * 7)


@pytest.mark.parametrize("text,degrees", [("A1", 0.0), ("A1+A2", 22.5), ("A3+A4+A5", 135.0),
                                          ("A8", 315.0), ("A2+A3+A4+A5+A6+A7+A8", 180.0)])
def test_forward_is_the_unit_mean_bisector(text, degrees):
    # 1e-12: sums of at most seven unit vectors, normalised
    np.testing.assert_allclose(Gait.parse(text).forward,
                               rotation(degrees) @ np.array([1.0, 0.0]), atol=1e-12)


@pytest.mark.parametrize("text", ["A1+A5", "A1+A3+A5+A7", ALL_ACTUATORS, "none"])
def test_forward_is_none_where_the_bisectors_cancel(text):
    assert Gait.parse(text).forward is None


@pytest.mark.parametrize("text", ["A1", "A1+A2", "A2+A5+A6", "A1+A3+A4+A8"])
def test_transform_rotates_and_reflects_the_forward_direction(text):
    """Rotating by r·45° turns the forward direction by r·45°; reflecting across the A1 axis
    mirrors its y (checked with rotation matrices, not with the index arithmetic)."""
    gait = Gait.parse(text)
    mirror = np.diag([1.0, -1.0])
    for turns in range(8):
        for reflect in (False, True):
            image = gait.transform(turns, reflect)
            assert len(image.actuators) == len(gait.actuators)
            direction = mirror @ gait.forward if reflect else gait.forward
            # 1e-12: as above
            np.testing.assert_allclose(image.forward, rotation(45.0 * turns) @ direction,
                                       atol=1e-12)


def test_transform_maps_actuator_numbers_around_the_octagon():
    assert Gait.parse("A1+A2").transform(1, False).name == "A2+A3"
    assert Gait.parse("A7+A8").transform(2, False).name == "A1+A2"
    assert Gait.parse("A2").transform(0, True).name == "A8"
    assert Gait.parse("A2+A4").transform(3, True).name == "A1+A3"
    assert Gait.parse("none").transform(5, True).name == "none"


def test_symmetric_images_are_the_distinct_images_sorted_by_bits():
    images = Gait.parse("A1+A2").symmetric_images
    assert [g.name for g in images] == ["A1+A2", "A2+A3", "A3+A4", "A4+A5", "A5+A6", "A6+A7",
                                        "A1+A8", "A7+A8"]
    assert [g.name for g in Gait.parse("A3+A7").symmetric_images] == [
        "A1+A5", "A2+A6", "A3+A7", "A4+A8"]


def test_symmetry_classes_cover_every_non_empty_gait_once():
    all_gaits = {"+".join(f"A{a}" for a in combination) for size in range(1, 9)
                 for combination in itertools.combinations(range(1, 9), size)}
    classes = symmetry_classes()
    members = [m for _, group in classes for m in group]
    assert sorted(members) == sorted(all_gaits)
    # one class each for the single actuators and for all eight
    assert ("A1", [f"A{a}" for a in range(1, 9)]) in classes
    assert (ALL_ACTUATORS, [ALL_ACTUATORS]) in classes
    # the representative is the member of smallest bits; classes come in order of it
    for representative, group in classes:
        assert representative == group[0]
        assert all(Gait.parse(g).transform(r, f).name in group
                   for g in group for r in range(8) for f in (False, True))
    first_bits = [Gait.parse(representative).bits for representative, _ in classes]
    assert first_bits == sorted(first_bits)
