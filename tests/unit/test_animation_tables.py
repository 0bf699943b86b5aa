"""taichi_star.output's tables for the studies, without simulation: the robot's edge table
against the built topology, and the animation tables with their inverse `replay`."""

import dataclasses
import io

import numpy as np
import pandas as pd
import pytest

from taichi_star import StarParams
from taichi_star.output import SHAPE_DECIMALS, animation_tables, edge_table, replay
from taichi_star.geometry import CENTRE, build_topology


@pytest.mark.parametrize("params", [StarParams(), StarParams(n_arc=4, n_limb=2)])
def test_the_edge_table_is_the_built_topology_named(params):
    """The rows are the topology's edges in its order; 8 spokes from the hub, then per joint
    its limb's n_limb edges chained from the joint to the tip and its arc's n_arc edges
    chained to the next joint, consecutive rows each, the arc's numbered by its actuator.
    E = 8·(1 + n_limb + n_arc) = N + 7: the spokes and limbs make a tree over the N nodes
    (N − 1 edges), each of the 8 arcs closes a loop."""
    table = edge_table(params)
    topology = build_topology(params)
    assert table.columns.tolist() == ["node_a", "node_b", "kind", "actuator"]
    np.testing.assert_array_equal(table[["node_a", "node_b"]].to_numpy(), topology.edges)
    n_limb, n_arc = params.n_limb, params.n_arc
    assert len(table) == 8 * (1 + n_limb + n_arc) == topology.n_nodes + 7
    assert set(table["node_a"]) | set(table["node_b"]) == set(range(topology.n_nodes))
    block = 1 + n_limb + n_arc
    for k in range(8):
        rows = table.iloc[k * block:(k + 1) * block]
        assert rows["kind"].tolist() == ["spoke"] + ["limb"] * n_limb + ["arc"] * n_arc
        assert tuple(rows.iloc[0][["node_a", "node_b"]]) == (CENTRE, topology.joints[k])
        limb = rows.iloc[1:1 + n_limb]
        np.testing.assert_array_equal(limb["node_a"], topology.limbs[k][:-1])
        np.testing.assert_array_equal(limb["node_b"], topology.limbs[k][1:])
        arc = rows.iloc[1 + n_limb:]
        np.testing.assert_array_equal(arc["node_a"], topology.arcs[k][:-1])
        np.testing.assert_array_equal(arc["node_b"], topology.arcs[k][1:])
        assert arc["node_b"].iloc[-1] == topology.joints[(k + 1) % 8]
        assert (arc["actuator"] == k + 1).all() and (rows.iloc[:1 + n_limb]["actuator"] == 0).all()
    assert (table[table["kind"] == "spoke"]["node_a"] == CENTRE).all()


def test_the_edge_table_wants_a_robot():
    with pytest.raises(ValueError, match="^params must be a StarParams, got dict$"):
        edge_table({"n_arc": 4})


@dataclasses.dataclass
class Recorded:
    """What `animation_tables` and `replay` read of a SimulationResult (a dataclass too)."""
    summary: pd.DataFrame
    trajectory: pd.DataFrame
    shapes: np.ndarray


def recorded_run():
    """Two robots of 3 nodes over 2 records (0 and 0.5 s), the second failed at the second
    record (NaN from there on, as `simulate` leaves it); positions in m with digits beyond
    SHAPE_DECIMALS of mm."""
    shapes = np.arange(2 * 2 * 3 * 2, dtype=float).reshape(2, 2, 3, 2) * 1e-3 + 1.23456789e-9
    shapes[1, 1] = np.nan
    trajectory = pd.DataFrame({"instance": [1, 1, 0, 0], "t_s": [0.0, 0.5, 0.0, 0.5],
                               "x_mm": [0.0, np.nan, 0.0, 2.5], "y_mm": [0.0, np.nan, 0.0, -1.0],
                               "heading_deg": [0.0, np.nan, 0.0, 4.0]})
    return Recorded(summary=pd.DataFrame({"status": ["ok", "newton_failed"]}),
                    trajectory=trajectory, shapes=shapes)


def test_animation_tables_hold_every_node_and_the_centroid_per_record():
    run = recorded_run()
    shapes, centroid = animation_tables(run, ["A1", "A1+A2"])
    assert shapes.columns.tolist() == ["gait", "frame", "t_s", "node", "x_mm", "y_mm"]
    assert len(shapes) == 12 and shapes["gait"].tolist() == ["A1"] * 6 + ["A1+A2"] * 6
    assert shapes["frame"].tolist() == [0, 0, 0, 1, 1, 1] * 2
    assert shapes["t_s"].tolist() == [0.0, 0.0, 0.0, 0.5, 0.5, 0.5] * 2
    assert shapes["node"].tolist() == [0, 1, 2] * 4
    # robot 1, frame 0, node 2: shapes[0, 1, 2] = (10, 11) mm + 1.23456789e-6 mm, rounded
    row = shapes[(shapes["gait"] == "A1+A2") & (shapes["frame"] == 0) & (shapes["node"] == 2)]
    assert row[["x_mm", "y_mm"]].values.tolist() == [[10.0, 11.0]]
    assert shapes["x_mm"].iloc[1] == round(2.0 + 1.23456789e-6, SHAPE_DECIMALS) == 2.0
    assert shapes[(shapes["gait"] == "A1+A2") & (shapes["frame"] == 1)]["x_mm"].isna().all()
    assert centroid.columns.tolist() == ["gait", "frame", "t_s", "x_mm", "y_mm"]
    assert centroid["gait"].tolist() == ["A1", "A1", "A1+A2", "A1+A2"]
    assert centroid["frame"].tolist() == [0, 1, 0, 1]
    assert centroid["x_mm"].tolist()[:2] == [0.0, 2.5] and centroid["y_mm"].iloc[1] == -1.0
    for labels in (["A1"], ["A1", "A1"]):
        with pytest.raises(ValueError, match="^labels must name the 2 instances, each once"):
            animation_tables(run, labels)
    with pytest.raises(ValueError, match="^result has no recorded shapes"):
        animation_tables(dataclasses.replace(run, shapes=None), ["A1", "A1+A2"])


def test_replay_puts_the_tables_read_back_from_csv_into_the_result():
    """Written as CSV (10 digits, as the studies write) and read back, the tables give the
    recorded shapes to SHAPE_DECIMALS decimals of mm (exactly: such a number has at most 10
    digits) and the trajectory, NaN after the failure; the summary stays the run's."""
    run = recorded_run()
    written = [pd.read_csv(io.StringIO(table.to_csv(index=False, float_format="%.10g")))
               # labels out of sorted order: each instance takes its own label's rows (taken
               # sorted, instance 0 got instance 1's shapes: a mutation audit, 2026-12)
               for table in animation_tables(run, ["B", "A"])]
    replayed = replay(run, *written)
    expected = np.round(run.shapes * 1e3, SHAPE_DECIMALS)
    np.testing.assert_array_equal(replayed.shapes * 1e3, expected)
    assert np.nanmax(np.abs(replayed.shapes - run.shapes)) <= 5e-9  # half of 1e-5 mm, in m
    assert replayed.summary is run.summary
    trajectory = replayed.trajectory.sort_values(["instance", "t_s"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(trajectory.drop(columns="heading_deg"),
                                  run.trajectory.drop(columns="heading_deg")
                                  .sort_values(["instance", "t_s"]).reset_index(drop=True))
    # the heading the tables do not hold is NaN, and the result is still a whole one (without
    # the column its to_xarray failed; an audit, 2026-12)
    assert trajectory["heading_deg"].isna().all()
    shapes, centroid = written
    with pytest.raises(ValueError, match="^shapes must hold every node of every frame"):
        replay(run, shapes.iloc[1:], centroid)
    with pytest.raises(ValueError, match="^shapes hold 1 gaits, the result 2 instances$"):
        replay(run, shapes[shapes["gait"] == "B"], centroid)
