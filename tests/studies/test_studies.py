"""Studies smoke tests (every study in --quick mode into tmp_path), the gait-symmetry test of
the gaits study, argument validation before compute, and the packaged experiment data."""

import math

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star.gait import Gait, symmetry_classes
from taichi_star.experiment import (FIG4C_COLUMNS, PAPER_DIRECTIONS, PAPER_GAITS,
                                    compare_with_experiment, experimental_speed,
                                    experimental_speeds, experimental_trajectory)

from studies import STUDIES, common, gaits as gaits_study
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]


def pngs_written(*paths):
    for path in paths:
        assert path.exists() and path.stat().st_size > 1000, path


# ----------------------------------------------------------------------------- experiment data

def test_experiment_data_is_packaged():
    speeds = experimental_speeds()
    assert list(speeds.index) == list(PAPER_GAITS)
    assert experimental_speed("A1+A2") == pytest.approx(2.85)
    assert experimental_speed("A2+A1") == pytest.approx(2.85)  # canonical gait names
    assert math.isnan(experimental_speed("A1+A6"))
    for gait in PAPER_GAITS:
        trajectory = experimental_trajectory(gait)
        assert list(trajectory.columns) == ["t_s", "x_mm", "y_mm", "displacement_mm"]
        assert trajectory["t_s"].iloc[0] == 0.0 and len(trajectory) > 1000
    with pytest.raises(ValueError, match="no experimental trajectory"):
        experimental_trajectory("A1+A6")


def test_compare_with_experiment_directions_and_failures():
    summary = pd.DataFrame({
        "gait": list(PAPER_GAITS),
        "speed_mm_s": [0.5, 2.0, 3.0, 1.0, 4.0],
        "signed_speed_mm_s": [0.5, 2.0, -3.0, 1.0, -4.0],
        "status": ["ok", "ok", "ok", "ok", "newton_failed"]})
    table = compare_with_experiment(summary)
    assert list(table.columns) == FIG4C_COLUMNS
    assert list(table["paper_direction"]) == [PAPER_DIRECTIONS[g] for g in PAPER_GAITS]
    assert list(table["sim_direction"][:4]) == ["forward", "forward", "reverse", "forward"]
    assert list(table["direction_matches"][:4]) == [True, True, True, False]
    assert table["speed_ratio"].iloc[1] == pytest.approx(2.0 / 2.85)
    # a failed instance never reports a speed
    assert math.isnan(table["sim_speed_mm_s"].iloc[4]) and table["status"].iloc[4] == "newton_failed"


# ----------------------------------------------------------------------------- argument parsing

def test_parse_values_and_ranges():
    assert common.parse_values("0.2:1.2:11", "--alpha") == pytest.approx(
        [0.2 + 0.1 * i for i in range(11)])
    assert common.parse_values("0,0.5,1", "--added-mass") == [0.0, 0.5, 1.0]
    assert common.parse_values("1e6:1e8:3:log", "--youngs-modulus") == pytest.approx(
        [1e6, 1e7, 1e8])
    assert common.parse_values("contract,always", "--jet-mode", str) == ["contract", "always"]
    for bad in ("0.2:1.2", "a:1:3", "0:1:x", "0:1:0", "1,,2", "1:2:3:lin", "nan"):
        with pytest.raises(common.StudyArgumentError, match="--alpha"):
            common.parse_values(bad, "--alpha")


def test_param_product_order_and_validation():
    grid = common.param_product({"gait": ["A1", "A1+A2"], "alpha": [0.5, 1.0]})
    assert [(p.gait, p.alpha) for p in grid] == [("A1", 0.5), ("A1", 1.0), ("A1+A2", 0.5),
                                                 ("A1+A2", 1.0)]
    with pytest.raises(common.StudyArgumentError, match="unknown parameter 'beta'"):
        common.param_product({"beta": [1.0]})
    with pytest.raises(common.StudyArgumentError, match="empty product"):
        common.param_product({"alpha": []})
    with pytest.raises(common.StudyArgumentError, match="alpha must be >= 0"):
        common.param_product({"alpha": [-1.0]})


@pytest.fixture
def no_compute(monkeypatch):
    """Any call to simulate fails the test: argument errors must come before compute."""
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    monkeypatch.setattr(taichi_star, "simulate", forbidden)


@pytest.mark.parametrize("study, argv, message", [
    ("sweep", ["--alpha", "0.2:1.2"], "--alpha: malformed range"),
    ("sweep", ["--alpha", "0.2:1.2:zero"], "--alpha: malformed range"),
    ("sweep", ["--param", "beta=1,2"], "unknown parameter 'beta'"),
    ("sweep", ["--gaits", ""], "empty"),
    ("sweep", ["--alpha", ""], "empty"),
    ("sweep", ["--gaits", "A1,A9"], "unknown actuator 'A9'"),
    ("sweep", ["--alpha=-1,1"], "alpha must be >= 0"),
    ("sweep", ["--jet-mode", "sometimes"], "jet_mode must be one of"),
    ("fig4c", ["--set", "gamma=1"], "unknown parameter 'gamma'"),
    ("fig4c", ["--set", "alpha=1,2"], "exactly one value"),
    ("calibrate", ["--fit", "alpha=1:2"], "malformed range"),
    ("calibrate", ["--fit", "jet_mode=contract,always"], "only real-valued"),
    ("calibrate", ["--fit", "alpha=0:1:2", "--fit", "period=3:4:2",
                   "--fit", "cylinder_drag=1:2:2"], "at most two"),
    ("gaits", ["--cycles", "0"], "--cycles must be > 0"),
    ("animate", ["--gait", "A0"], "--gait"),
])
def test_invalid_arguments_fail_before_compute(no_compute, tmp_path, capsys, study, argv,
                                               message):
    code = studies_main([study, *argv, "--out", str(tmp_path), *QUICK])
    assert code == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert not any(tmp_path.iterdir())  # nothing written


def test_unknown_study_and_unknown_flag(no_compute, capsys):
    assert studies_main(["fig4d"]) == 2
    assert "unknown study 'fig4d'" in capsys.readouterr().err
    assert studies_main(["sweep", "--betta", "1"]) == 2
    assert "unrecognized arguments: --betta" in capsys.readouterr().err
    assert {"fig4c", "sweep", "gaits", "calibrate", "animate"} <= set(STUDIES)


# ----------------------------------------------------------------------------- studies, quick

def test_fig4c_quick(tmp_path):
    from studies import fig4c
    fig4c.main(["--out", str(tmp_path), *QUICK])
    table = pd.read_csv(tmp_path / "fig4c.csv")
    assert list(table.columns) == FIG4C_COLUMNS
    assert list(table["gait"]) == list(PAPER_GAITS)
    assert set(table["sim_direction"]) <= {"forward", "reverse", "undefined"}
    assert (table["status"] == "ok").all()
    assert np.isfinite(table["sim_speed_mm_s"]).all() and (table["sim_speed_mm_s"] > 0).all()
    assert table["exp_speed_mm_s"].tolist() == pytest.approx([0.428, 2.85, 3.37, 3.349, 2.748])
    summary = pd.read_csv(tmp_path / "fig4c_summary.csv")
    assert len(summary) == 5 and "newton_iterations_max" in summary
    curves = pd.read_csv(tmp_path / "fig4b.csv")
    assert set(curves["source"]) == {"simulation", "experiment"}
    assert curves["t_s"].max() <= common.QUICK_DURATION_S + 1e-9
    pngs_written(tmp_path / "fig4c.png", tmp_path / "fig4b.png")


def test_sweep_quick(tmp_path):
    from studies import sweep
    sweep.main(["--out", str(tmp_path), "--alpha", "0.4:1.2:3", "--jet-mode", "contract,always",
                "--gaits", "A1,A1+A3", *QUICK])
    table = pd.read_csv(tmp_path / "sweep.csv")
    assert len(table) == 2 * 3 * 2
    for column in ["gait", "alpha", "jet_mode", "speed_mm_s", "signed_speed_mm_s",
                   "heading_deg", "status", "instance"] + StarParams.field_names():
        assert column in table, column
    assert table["instance"].tolist() == list(range(12))
    assert (table["status"] == "ok").all()
    # the alpha axis matters for a jetting gait
    a13 = table[(table["gait"] == "A1+A3") & (table["jet_mode"] == "contract")]
    assert a13["speed_mm_s"].nunique() == 3
    pngs_written(tmp_path / "sweep_alpha.png", tmp_path / "sweep_jet_mode.png")


def test_gaits_quick(tmp_path):
    gaits_study.main(["--out", str(tmp_path), *QUICK])
    table = pd.read_csv(tmp_path / "gaits.csv")
    assert list(table.columns) == gaits_study.GAITS_COLUMNS
    assert len(table) == 255 and table["gait"].is_unique
    assert table["class_representative"].nunique() == 29
    assert (table.groupby("class_representative")["class_size"].first().sum()) == 255
    classes = pd.read_csv(tmp_path / "gaits_classes.csv")
    assert len(classes) == 29
    pngs_written(tmp_path / "gaits.png")


def test_calibrate_quick(tmp_path):
    from studies import calibrate
    calibrate.main(["--out", str(tmp_path), *QUICK])
    table = pd.read_csv(tmp_path / "calibration.csv")
    assert len(table) >= 4 and set(table["round"]) == {0, 1}
    for column in ["alpha", "cylinder_drag", "objective", "n_direction_mismatches",
                   "speed_A1+A2", "signed_speed_A1+A3+A5"]:
        assert column in table, column
    fit = pd.read_csv(tmp_path / "calibration_fit.csv")
    assert list(fit["parameter"]) == ["alpha", "cylinder_drag"]
    assert fit["objective"].iloc[0] == pytest.approx(table["objective"].min())
    calibrated = pd.read_csv(tmp_path / "fig4c_calibrated.csv")
    assert list(calibrated.columns) == FIG4C_COLUMNS
    pngs_written(tmp_path / "calibration.png", tmp_path / "fig4c_calibrated.png")


def test_animate_quick(tmp_path):
    from PIL import Image
    from studies import animate
    animate.main(["--out", str(tmp_path), "--frames", "5", *QUICK])
    folder = tmp_path / "animations"
    with Image.open(folder / "A1_A2.gif") as gif:
        assert gif.n_frames >= 5
    shapes = pd.read_csv(folder / "shapes.csv")
    assert list(shapes.columns) == ["gait", "frame", "t_s", "node", "x_mm", "y_mm"]
    assert shapes["node"].nunique() == 193
    edges = pd.read_csv(folder / "edges.csv")
    assert len(edges) == 200 and set(edges["actuator"]) == set(range(9))


# ----------------------------------------------------------------------------- symmetry

def test_symmetry_reduction_is_exact():
    """A rotated or mirrored gait swims at the same speed (to solver tolerance) along the
    rotated / mirrored heading: the basis of simulating one gait per class."""
    source = "A1+A2+A4"  # no symmetry of its own: a class of 16
    images = [(0, False), (3, False), (0, True), (5, True)]
    gaits = [Gait.parse(source).transform(r, f).name for r, f in images]
    assert len(set(gaits)) == 4
    duration = 0.2
    result = taichi_star.simulate([StarParams(gait=g) for g in gaits], duration,
                                  solver=SolverConfig(dt=2e-3))
    summary = result.summary
    assert (summary["status"] == "ok").all()
    speed = summary["speed_mm_s"].to_numpy()
    assert speed[0] > 0.05  # it moves: the comparison is not trivial
    assert np.allclose(speed, speed[0], rtol=1e-6, atol=1e-9)
    assert np.allclose(summary["signed_speed_mm_s"], summary["signed_speed_mm_s"].iloc[0],
                       rtol=1e-6, atol=1e-9)
    # tolerance on the heading: displacement ~ speed*duration mm, resolved to ~1e-9 mm
    for (rotation, reflect), heading in zip(images, summary["heading_deg"]):
        expected = gaits_study.transform_heading(summary["heading_deg"].iloc[0], rotation, reflect)
        assert abs(gaits_study.wrap_degrees(heading - expected)) < 1e-4
    # and the class expansion agrees with these direct simulations
    rep_class = next(c for c in symmetry_classes() if source in c[1])
    assert set(gaits) <= set(rep_class[1])
    for gait, heading in zip(gaits, summary["heading_deg"]):
        mapping = gaits_study.symmetry_map(source, gait)
        assert Gait.parse(source).transform(*mapping).name == gait
        assert abs(gaits_study.wrap_degrees(
            gaits_study.transform_heading(summary["heading_deg"].iloc[0], *mapping)
            - heading)) < 1e-4
