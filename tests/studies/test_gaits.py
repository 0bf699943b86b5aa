"""The gaits study's expansion of the 29 class representatives onto the 255 gaits
(`studies.gaits.expand_classes`), without simulation: every gait reads its representative's
speeds, its direction and heading mapped by the octagon symmetry (the library's
`taichi_star.primitives` functions), rows in the library's gait order."""

import math

import numpy as np
import pandas as pd
import pytest

from taichi_star import Gait, symmetry_classes

from studies import gaits as gaits_study

DIRECTION_DEG, HEADING_DEG = 10.0, 3.0
"""Every moving representative's travel direction and final heading in the summary below."""
FAILED, STILL = "A1+A2+A3", "A1+A5"
"""A representative whose run failed, and one that does not move (no forward direction)."""


def representatives_summary() -> pd.DataFrame:
    """A summary of the 29 representatives as `run_batch` gives it: representative k at speed
    k + 1 mm/s (signed the same, steady twice that, steady signed its negative), travelling
    along DIRECTION_DEG and turned by HEADING_DEG; FAILED failed (its metrics NaN), STILL
    stands still (its direction the angle of round-off)."""
    rows = []
    for index, (gait, _) in enumerate(symmetry_classes()):
        speed = float(index + 1)
        rows.append({"gait": gait, "speed_mm_s": speed, "signed_speed_mm_s": speed,
                     "steady_speed_mm_s": 2 * speed, "steady_signed_speed_mm_s": -speed,
                     "travel_direction_deg": DIRECTION_DEG, "heading_deg": HEADING_DEG,
                     "status": "ok"})
    summary = pd.DataFrame(rows)
    metrics = ["speed_mm_s", "signed_speed_mm_s", "steady_speed_mm_s",
               "steady_signed_speed_mm_s", "travel_direction_deg", "heading_deg"]
    summary.loc[summary["gait"] == FAILED, metrics] = math.nan
    summary.loc[summary["gait"] == FAILED, "status"] = "newton_failed"
    summary.loc[summary["gait"] == STILL, ["speed_mm_s", "travel_direction_deg"]] = [1e-12, 123.0]
    return summary


def test_every_gait_reads_its_representative_through_the_symmetry():
    """The images of A1+A2+A4 (a class of 16): A3+A4+A6 is it turned by 2·45° (direction
    10 -> 100, heading kept), A4+A6+A7 it mirrored and turned by 6·45° (direction -10 + 270 =
    -100, heading negated); a direction relative to the gait's own forward direction is the
    representative's, negated by a reflection. The failed class is NaN throughout with its
    status, the still class has no direction."""
    summary = representatives_summary()
    table = gaits_study.expand_classes(summary).set_index("gait")
    assert len(table) == 255
    assert table.groupby("class_representative")["class_size"].first().sum() == 255
    speed = float(summary.set_index("gait").loc["A1+A2+A4", "speed_mm_s"])
    expected = {"A1+A2+A4": (0, False, 10.0, 3.0), "A3+A4+A6": (2, False, 100.0, 3.0),
                "A4+A6+A7": (6, True, -100.0, -3.0)}
    relative = table.loc["A1+A2+A4", "travel_direction_relative_deg"]
    assert relative == pytest.approx(10.0 - math.degrees(math.atan2(math.sqrt(2 / 3),
                                                                    math.sqrt(1 / 3))), abs=1e-12)
    for gait, (rotation, reflected, direction, heading) in expected.items():
        row = table.loc[gait]
        assert row["class_representative"] == "A1+A2+A4" and row["class_size"] == 16
        assert (row["rotation"], row["reflected"]) == (rotation, reflected)
        assert Gait.parse("A1+A2+A4").transform(rotation, reflected).name == gait
        assert row[["speed_mm_s", "signed_speed_mm_s", "steady_speed_mm_s",
                    "steady_signed_speed_mm_s"]].tolist() == [speed, speed, 2 * speed, -speed]
        # 45° steps of an exact direction stay exact (no cos/sin round trip)
        assert (row["travel_direction_deg"], row["heading_deg"]) == (direction, heading)
        assert row["travel_direction_relative_deg"] == pytest.approx(
            -relative if reflected else relative, abs=1e-12)
        assert row["n_actuators"] == 3 and row["status"] == "ok"
    failed = table[table["class_representative"] == FAILED]
    assert len(failed) == 8 and (failed["status"] == "newton_failed").all()
    assert failed[["speed_mm_s", "travel_direction_deg", "heading_deg"]].isna().all().all()
    still = table[table["class_representative"] == STILL]
    assert len(still) == 4 and still["travel_direction_deg"].isna().all()
    assert still["travel_direction_relative_deg"].isna().all()
    assert (still["heading_deg"] == HEADING_DEG).all()  # A1+A5 is its own mirror image


def test_the_gaits_come_in_order_of_actuator_count_then_bits():
    """The rows: the 8 single actuators A1..A8, then the pairs from A1+A2 (bits 3), A1+A3
    (5), A2+A3 (6), ..., the eight-actuator gait last; the index 0..254."""
    table = gaits_study.expand_classes(representatives_summary())
    gaits = table["gait"].tolist()
    assert gaits[:11] == [f"A{k}" for k in range(1, 9)] + ["A1+A2", "A1+A3", "A2+A3"]
    assert gaits[-1] == "+".join(f"A{k}" for k in range(1, 9))
    keys = [(len(Gait.parse(g).actuators), Gait.parse(g).bits) for g in gaits]
    assert keys == sorted(keys) and len(set(gaits)) == 255
    np.testing.assert_array_equal(table.index, np.arange(255))


def test_where_the_actuators_differ_every_gait_is_simulated_and_read_as_itself(tmp_path):
    """With one actuator's gain changed a gait's images are other robots: the study simulates
    all 255 gaits and each row is that gait's own run, equal to a direct simulation (it copied
    the 29 representatives' runs onto the others: A3 read A1's, 0.52 mm/s at 90° where A3
    itself swims 2.47 mm/s, an audit); equal actuators keep the 29 representatives."""
    from taichi_star import SolverConfig, StarParams, simulate
    assert [p.gait for p in gaits_study.class_params(StarParams())] == [
        rep for rep, _ in symmetry_classes()]
    uneven = StarParams(actuator_gains=(1.0, 1.0, 1.4) + (1.0,) * 5)
    assert len(gaits_study.class_params(uneven)) == 255
    table = gaits_study.main(["--set", "actuator_gains=1,1,1.4,1,1,1,1,1", "--quick",
                              "--no-progress", "--out", str(tmp_path / "gaits")])
    assert (table["class_size"] == 1).all()
    assert (table["class_representative"] == table["gait"]).all()
    direct = simulate([uneven.replace(gait=g) for g in ("A1", "A3")], 0.2,
                      SolverConfig(dt=2e-3), progress=False).summary.set_index("gait")
    rows = table.set_index("gait")
    for gait in ("A1", "A3"):
        assert rows.loc[gait, "speed_mm_s"] == direct.loc[gait, "speed_mm_s"]
        # A1 swims along its own axis: its direction is 0 up to round-off (2e-12°), which
        # the study's records and the direct run's reach by other sums
        assert rows.loc[gait, "travel_direction_deg"] == pytest.approx(
            direct.loc[gait, "travel_direction_deg"], abs=1e-9)
    assert rows.loc["A3", "speed_mm_s"] != rows.loc["A1", "speed_mm_s"]
