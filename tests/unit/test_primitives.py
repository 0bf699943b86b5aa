"""taichi_star.primitives without simulation: the body-frame vectors follow the gait symmetry."""

import math

import numpy as np
import pytest

import taichi_star as ts
from taichi_star.metrics import wrap_degrees
from taichi_star.primitives import transform_direction, transform_rotation, transform_vectors


def test_transform_vectors_follows_the_gait_symmetry():
    """A1's bisector (1, 0) goes where Gait.transform sends A1."""
    for rotation in range(8):
        for reflect in (False, True):
            image = ts.Gait.parse("A1+A2").transform(rotation, reflect).forward
            vector = transform_vectors(ts.Gait.parse("A1+A2").forward, rotation, reflect)
            np.testing.assert_allclose(vector, image, atol=1e-15)


@pytest.mark.parametrize("direction_deg", [0.0, 22.5, 180.0, -180.0, -135.0, 37.3, -0.4])
@pytest.mark.parametrize("rotation, reflect", [(0, False), (4, False), (3, True), (0, True),
                                               (7, True)])
def test_direction_images_are_the_vector_symmetry_in_minus_180_to_180_included(
        direction_deg, rotation, reflect):
    """A direction's image: the angle of `transform_vectors`'s image of its unit vector (1e-12
    deg: atan2 of a unit vector rounded at 1e-16, in degrees), exact on 45° multiples, and in
    (-180, 180]: a gait travelling straight back reads 180, as the gaits study's committed
    table does."""
    image = transform_direction(direction_deg, rotation, reflect)
    angle = math.radians(direction_deg)
    vector = transform_vectors(np.array([math.cos(angle), math.sin(angle)]), rotation, reflect)
    assert abs(wrap_degrees(image - math.degrees(math.atan2(vector[1], vector[0])))) < 1e-12
    assert -180.0 < image <= 180.0
    if direction_deg % 45.0 == 0.0:
        assert image % 45.0 == 0.0


def test_a_body_rotation_is_reversed_by_a_reflection_alone():
    """A turn keeps its sign under a rotation of the gait and flips under a reflection, for a
    number and for an array (the per-cycle table's column)."""
    assert transform_rotation(12.5, False) == 12.5 and transform_rotation(12.5, True) == -12.5
    np.testing.assert_array_equal(transform_rotation(np.array([3.0, -1.5]), True), [-3.0, 1.5])
    np.testing.assert_array_equal(transform_rotation(np.array([3.0, -1.5]), False), [3.0, -1.5])


def test_the_symmetry_helpers_take_a_symmetry_or_refuse_naming_the_argument():
    """A rotation of 1.5 turns gave a direction no symmetry gives, and reflect="yes" or "no"
    reflected (an audit, 2026-12); as `Gait.transform`, a whole number of 45° turns and a
    boolean are taken (numpy's too), anything else is refused naming the argument."""
    assert transform_direction(10.0, np.int64(2), np.bool_(True)) == 80.0
    for rotation in (1.5, "1", None):
        with pytest.raises(ValueError, match="^rotation must be an integer"):
            transform_direction(10.0, rotation, False)
        with pytest.raises(ValueError, match="^rotation must be an integer"):
            transform_vectors(np.array([1.0, 0.0]), rotation, False)
    for reflect in ("yes", "no", 1, None):
        with pytest.raises(ValueError, match="^reflect must be True or False"):
            transform_direction(10.0, 1, reflect)
        with pytest.raises(ValueError, match="^reflect must be True or False"):
            transform_rotation(3.0, reflect)


@pytest.mark.parametrize("side, direction", [(1e-13, 180.0), (-1e-13, 180.0), (0.0, 180.0),
                                             (-0.0, 180.0), (-1e-8, 180.0),
                                             (2e-8, 180.0 - math.degrees(2e-9)),
                                             (-2e-8, -180.0 + math.degrees(2e-9))])
def test_a_step_along_minus_x_points_at_180_whatever_the_sign_of_its_rounding(side, direction):
    """A gait symmetric about the x axis stepping along -x has a side component of rounding
    (1e-13 mm), whose sign made its direction -180 or 180 (five gaits flipped between two
    measurements; an audit, 2026-12): within 1e-9 of the step's length (1e-8 of 10 mm, the
    bound included) it is 0, the direction 180; beyond it (2e-8) it keeps its side."""
    from taichi_star.primitives import _step_direction

    assert _step_direction(np.array([-10.0, side])) == pytest.approx(direction, abs=1e-12)


def test_actuators_equal_decides_between_the_symmetry_classes_and_all_gaits():
    """One gait per symmetry class stands for its images only if every per-actuator field
    holds one value: exactly equal values (non-default ones too) keep the 29 classes; a gain
    one ulp apart, a delay on one actuator or the identified preset's gains need all 255 gaits,
    each its own source with no symmetry."""
    import math

    from taichi_star.primitives import (actuators_equal, class_symmetries, gait_sources,
                                        simulated_gaits)

    equal = ts.StarParams(actuator_gains=(1.3,) * 8, actuator_delays=(0.05,) * 8)
    assert actuators_equal(equal) and actuators_equal(ts.StarParams())
    unequal = [equal.replace(actuator_gains=(1.3,) * 7 + (math.nextafter(1.3, 2.0),)),
               ts.StarParams(actuator_delays=(0.0,) * 7 + (0.01,)),
               ts.StarParams.preset("identified")]
    assert not any(actuators_equal(params) for params in unequal)
    reduced, direct = gait_sources(True), gait_sources(False)
    assert reduced == class_symmetries() and len(simulated_gaits(reduced)) == 29
    assert simulated_gaits(reduced) == [name for name, _ in ts.symmetry_classes()]
    assert set(direct) == set(reduced) and len(direct) == 255
    assert simulated_gaits(direct) == list(direct)
    assert all(source == (gait, 0, False, 1) for gait, source in direct.items())


def test_cycle_displacements_are_in_the_frame_the_body_had_when_the_cycle_began():
    """One robot over three 2-s cycles: facing +y it moves (0, 5) (body frame: 5 mm ahead),
    turns from 170° to −170° (a +20° rotation, wrapped), then moves (−3, 0) facing −170°; a
    record between two boundaries is left out; a second robot that stands still."""
    import pandas as pd

    from taichi_star.primitives import cycle_displacements

    trajectory = pd.DataFrame({                   # the still robot's rows first: sorted out
        "instance": [1, 1, 0, 0, 0, 0, 0],
        "t_s": [0.0, 2.0, 0.0, 2.0, 3.0, 4.0, 6.0],
        "x_mm": [1.0, 1.0, 0.0, 0.0, 9.0, 0.0, -3.0],
        "y_mm": [1.0, 1.0, 0.0, 5.0, 9.0, 5.0, 5.0],
        "heading_deg": [0.0, 0.0, 90.0, 170.0, 0.0, -170.0, -170.0]})
    table = cycle_displacements(trajectory, 2.0)
    assert table.columns.tolist() == ["instance", "cycle", "dx_body_mm", "dy_body_mm",
                                      "rotation_deg"]
    assert table.instance.tolist() == [0, 0, 0, 1] and table.cycle.tolist() == [0, 1, 2, 0]
    assert table.index.tolist() == [0, 1, 2, 3] and table.cycle.dtype.kind == "i"
    turned = np.radians(-170.0)
    expected = [(5.0, 0.0), (0.0, 0.0),
                (-3.0 * np.cos(turned), 3.0 * np.sin(turned)), (0.0, 0.0)]
    np.testing.assert_allclose(table[["dx_body_mm", "dy_body_mm"]], expected, atol=1e-12)
    np.testing.assert_allclose(table.rotation_deg, [80.0, 20.0, 0.0, 0.0], atol=1e-12)


def cycles_of(gait, steps, turns, status="ok"):
    import pandas as pd
    return pd.DataFrame({"gait": gait, "cycle": range(len(steps)),
                         "dx_body_mm": [s[0] for s in steps], "dy_body_mm": [s[1] for s in steps],
                         "rotation_deg": turns, "status": status})


def test_a_summary_takes_the_mean_of_its_cycles_not_the_median():
    """Four steady cycles of 9, 1, 2 and 6 mm and degrees: the mean 4.5, the median 4 (every
    other test averages at most two cycles, where they agree: a mutation audit, 2026-12)."""
    from taichi_star.primitives import summarise_cycles

    values = [0.0, 9.0, 1.0, 2.0, 6.0]  # cycle 0 is not counted
    cycles = cycles_of("A1", [(v, v) for v in values], values).assign(
        class_representative="A1", symmetry_rotation=0, reflected=False)
    row = summarise_cycles(cycles, 1, {"A1": ("A1", 0, False, 8)}).iloc[0]
    assert (row.step_x_mm, row.step_y_mm, row.turn_deg) == (4.5, 4.5, 4.5)


def test_expanded_cycles_are_the_sources_turned_and_mirrored():
    """A source's cycles read for an image gait: steps turned by rotation·45° (mirrored first
    when reflected), turns negated when reflected; rows sorted by gait then cycle."""
    import pandas as pd

    from taichi_star.primitives import CYCLE_COLUMNS, expand_cycles

    source = cycles_of("A1", [(2.0, 1.0), (4.0, 0.0)], [10.0, -5.0], "ok").iloc[::-1]
    sources = {"A1": ("A1", 0, False, 8), "A3": ("A1", 2, False, 8), "A8": ("A1", 0, True, 8)}
    table = expand_cycles(pd.concat([source]), sources)
    assert table.columns.tolist() == CYCLE_COLUMNS
    assert table.gait.tolist() == ["A1", "A1", "A3", "A3", "A8", "A8"]
    assert table.cycle.tolist() == [0, 1] * 3
    np.testing.assert_allclose(table[["dx_body_mm", "dy_body_mm"]],
                               [(2, 1), (4, 0), (-1, 2), (0, 4), (2, -1), (4, 0)], atol=1e-12)
    np.testing.assert_array_equal(table.rotation_deg, [10, -5, 10, -5, -10, 5])
    assert table.class_representative.tolist() == ["A1"] * 6
    assert table.symmetry_rotation.tolist() == [0, 0, 2, 2, 0, 0]
    assert table.reflected.tolist() == [False, False, False, False, True, True]
    assert table.index.tolist() == list(range(6))


def test_a_summary_averages_the_cycles_from_the_first_one_counted():
    """Mean step and turn over cycles ≥ first_cycle with their sample spread (ddof 1; NaN for
    one cycle), the direction of the mean step (NaN below ZERO_STEP_MM, defined at it), the
    class size from the sources and the cycles run; gaits sorted by actuator count then
    bits."""
    import math

    import pandas as pd

    from taichi_star.primitives import ZERO_STEP_MM, summarise_cycles

    cycles = pd.concat([
        cycles_of("A1+A2", [(99.0, 99.0), (1.0, 1.0), (3.0, 5.0)], [50.0, 2.0, 4.0]),
        cycles_of("A1", [(99.0, 0.0), (ZERO_STEP_MM, 0.0), (ZERO_STEP_MM, 0.0)], [0.0] * 3),
        cycles_of("A2", [(0.0, 0.0), (0.0, 0.0), (0.0, 0.0)], [0.0] * 3, "nan_state"),
    ]).assign(class_representative="A1", symmetry_rotation=0, reflected=False)
    cycles.loc[cycles.gait == "A1+A2", ["class_representative", "symmetry_rotation",
                                        "reflected"]] = ["A1+A4", 6, True]
    sources = {"A1": ("A1", 0, False, 8), "A2": ("A1", 1, False, 8),
               "A1+A2": ("A1+A2", 0, False, 4)}
    table = summarise_cycles(cycles, 1, sources)
    assert table.gait.tolist() == ["A1", "A2", "A1+A2"]
    pair = table.set_index("gait").loc["A1+A2"]
    assert (pair.step_x_mm, pair.step_y_mm, pair.turn_deg) == (2.0, 3.0, 3.0)
    assert pair.step_x_std_mm == pytest.approx(math.sqrt(2.0), rel=1e-15)
    assert pair.step_y_std_mm == pytest.approx(math.sqrt(8.0), rel=1e-15)
    assert pair.turn_std_deg == pytest.approx(math.sqrt(2.0), rel=1e-15)
    assert pair.step_mm == pytest.approx(math.hypot(2.0, 3.0), rel=1e-15)
    assert pair.direction_deg == pytest.approx(math.degrees(math.atan2(3.0, 2.0)), rel=1e-15)
    assert (pair.class_size, pair.n_actuators, pair.first_cycle, pair.cycles) == (4, 2, 1, 3)
    assert (pair.class_representative, pair.symmetry_rotation, pair.reflected) == ("A1+A4", 6,
                                                                                   True)
    rows = table.set_index("gait")
    assert rows.loc["A1", "direction_deg"] == 0.0                    # a step of exactly the floor
    assert math.isnan(rows.loc["A2", "direction_deg"]) and rows.loc["A2", "status"] == "nan_state"
    one = summarise_cycles(cycles, 2, sources).set_index("gait")
    assert math.isnan(one.loc["A1+A2", "step_x_std_mm"]) and one.loc["A1+A2", "step_x_mm"] == 3.0
    assert math.isnan(one.loc["A1+A2", "turn_std_deg"])


def test_the_cycle_helpers_refuse_what_would_read_wrong_cycles():
    """A trajectory without a record at a cycle boundary read two cycles as one (records at 0,
    2T, 4T gave "cycles" 0 and 2, 10 mm each), summarise_cycles took first_cycle -3 and gave
    a raw KeyError for one past the table, expand_cycles a raw KeyError for a source it lacks,
    gait_sources took "no" for True (an audit, 2026-12): each a ValueError naming it; the
    last cycle itself is a first_cycle it takes."""
    import pandas as pd

    from taichi_star.primitives import (cycle_displacements, expand_cycles, gait_sources,
                                        summarise_cycles)

    skipping = pd.DataFrame({"instance": 0, "t_s": [0.0, 4.0, 8.0], "x_mm": [0.0, 10.0, 20.0],
                             "y_mm": 0.0, "heading_deg": 0.0})
    with pytest.raises(ValueError, match=r"^trajectory: instance 0 has no record at the cycle "
                                         r"boundary after t = 0 s"):
        cycle_displacements(skipping, 2.0)
    assert cycle_displacements(skipping, 4.0).cycle.tolist() == [0, 1]
    # a boundary recorded twice is said to be so, not to lack the record after it (its
    # zero-length "cycle" was taken for a gap: a mutation audit, 2026-12)
    twice = pd.DataFrame({"instance": 0, "t_s": [0.0, 2.0, 2.0, 4.0], "y_mm": 0.0,
                          "x_mm": [0.0, 10.0, 10.0, 20.0], "heading_deg": 0.0})
    with pytest.raises(ValueError, match=r"^trajectory: instance 0 has two records at the "
                                         r"cycle boundary t = 2 s \(records at every"):
        cycle_displacements(twice, 2.0)
    # boundaries written as rounded decimals (k·0.1 s to 10 digits) are each their cycle's
    decimal = pd.DataFrame({"instance": 0, "t_s": [round(k * 0.1, 10) for k in range(31)],
                            "x_mm": np.arange(31.0), "y_mm": 0.0, "heading_deg": 0.0})
    assert cycle_displacements(decimal, 0.1).cycle.tolist() == list(range(30))
    cycles = cycles_of("A1", [(1.0, 0.0), (2.0, 0.0), (3.0, 0.0)], [0.0] * 3).assign(
        class_representative="A1", symmetry_rotation=0, reflected=False)
    sources = {"A1": ("A1", 0, False, 1)}
    assert summarise_cycles(cycles, 2, sources).step_x_mm.tolist() == [3.0]
    for first_cycle in (-1, 3, 1.0, True):
        with pytest.raises(ValueError, match=rf"^first_cycle must be an integer in \[0, 2\] "
                                             rf"\(the table's cycles\), got {first_cycle!r}$"):
            summarise_cycles(cycles, first_cycle, sources)
    with pytest.raises(ValueError, match=r"^representatives: no rows of gait A1\+A3 \(1 "):
        expand_cycles(cycles, {"A1": ("A1", 0, False, 1), "A3": ("A1+A3", 1, False, 1)})
    with pytest.raises(ValueError, match=r"^symmetric must be True or False, got 'no'$"):
        gait_sources("no")


def test_widened_tables_put_each_streak_in_its_own_columns():
    import pandas as pd

    from taichi_star.primitives import widen_glides, widen_steps

    steps = widen_steps(pd.concat([cycles_of("A1", [(1.0, 2.0), (3.0, 4.0)], [0.0, 0.0]),
                                   cycles_of("A2", [(5.0, 6.0), (7.0, 8.0)], [0.0, 0.0])]))
    assert steps.columns.tolist() == ["gait", "step1_x_mm", "step1_y_mm", "step2_x_mm",
                                      "step2_y_mm"]
    assert steps.values.tolist() == [["A1", 1.0, 2.0, 3.0, 4.0], ["A2", 5.0, 6.0, 7.0, 8.0]]
    glides = widen_glides(pd.DataFrame({
        "gait": ["A1", "A1", "A2", "A2"], "glide_fire_cycles": [1, 2, 1, 2],
        "glide_x_mm": [1.0, 2.0, 3.0, 4.0], "glide_y_mm": [-1.0, -2.0, -3.0, -4.0],
        "glide_cycles": [4, 4, 4, 4]}))
    assert glides.columns.tolist() == ["gait", "glide1_x_mm", "glide1_y_mm", "glide2_x_mm",
                                       "glide2_y_mm", "glide_cycles"]
    assert glides.values.tolist() == [["A1", 1.0, -1.0, 2.0, -2.0, 4],
                                      ["A2", 3.0, -3.0, 4.0, -4.0, 4]]


def test_gaits_sort_by_actuator_count_then_bits_then_the_extra_keys():
    import pandas as pd

    from taichi_star.primitives import sort_gaits

    table = pd.DataFrame({"gait": ["A1+A2", "A3", "A1", "A3", "A8"], "cycle": [0, 1, 0, 0, 0]})
    ordered = sort_gaits(table, extra=["cycle"])
    assert ordered.values.tolist() == [["A1", 0], ["A3", 0], ["A3", 1], ["A8", 0], ["A1+A2", 0]]
    assert ordered.columns.tolist() == ["gait", "cycle"] and ordered.index.tolist() == [0, 1, 2,
                                                                                         3, 4]


def test_a_measurement_is_checked_at_the_ends_of_its_ranges_before_any_compute():
    """cycles ≥ 1 and first_cycle in [0, cycles − 1], both integers (a bool is not one), and
    the period a whole number of steps: each end accepted, just past it refused, naming the
    argument and its range."""
    from taichi_star.primitives import check_measurement

    base, solver = ts.StarParams(), ts.SolverConfig()
    check_measurement(base, solver, cycles=1, first_cycle=0)
    check_measurement(base, solver, cycles=3, first_cycle=2)
    for cycles in (0, True, 2.0):
        with pytest.raises(ValueError, match=rf"^cycles must be an integer >= 1, got {cycles!r}$"):
            check_measurement(base, solver, cycles=cycles, first_cycle=0)
    for first_cycle in (3, -1, False):
        with pytest.raises(ValueError, match=rf"^first_cycle must be an integer in \[0, 2\], got "
                                             rf"{first_cycle!r}$"):
            check_measurement(base, solver, cycles=3, first_cycle=first_cycle)
    with pytest.raises(ValueError, match=r"^period must be a whole number of steps \(dt = 0.001 "
                                         r"s\) to record every cycle boundary, got 3.1505$"):
        check_measurement(base.replace(period=3.1505), solver, cycles=2, first_cycle=1)


@pytest.mark.parametrize("base, simulated", [(ts.StarParams(), 29),
                                             (ts.StarParams.preset("identified"), 255)])
def test_measuring_simulates_the_classes_or_every_gait_as_the_actuators_say(monkeypatch, base,
                                                                             simulated):
    """measure_primitives and measure_glides pass on the sources `actuators_equal` chooses: the
    identified preset's robot, whose actuators differ, simulates every gait, not its mirror
    images (either call with the reduced sources hard-coded passed every test: a mutation
    audit, 2026-12). The measurement itself is replaced: nothing is simulated."""
    from taichi_star import primitives

    given = []
    for name in ("primitives_from_sources", "glides_from_sources"):
        monkeypatch.setattr(primitives, name, lambda base, solver, sources, *rest:
                            given.append(primitives.simulated_gaits(sources)))
    primitives.measure_primitives(base, ts.SolverConfig(dt=5e-3), cycles=2)
    primitives.measure_glides(base, ts.SolverConfig(dt=5e-3), fire_cycles=1, glide_cycles=1)
    assert [len(gaits) for gaits in given] == [simulated, simulated]
