"""The elasticities study (`python -m studies elasticities`): its table against its own columns,
the committed Sobol table and whole-run finite differences, and its refusals."""

import numpy as np
import pandas as pd
import pytest

from studies import cli
from studies import elasticities as study
from studies.__main__ import main as studies_main

GAIT = "A1+A3"
PARAMETERS = ("alpha", "drag_perpendicular", "actuator_gains[0]", "actuator_gains[1]",
              "damping_time")
"""Two Sobol parameters, the gain of a fired (A1) and of an idle (A2) actuator, and a parameter
at 0 in the paper's model: 1 + 4·5 = 21 instances, the smallest engine."""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """One quick run (0.2 s at 2 ms). Its cost is the compilation of the engine that carries
    tangents (measured 35-113 s on the shared 2-core machine); the steps take under a second."""
    out = tmp_path_factory.mktemp("elasticities")
    # the committed Sobol table is the accurate preset's, this run the paper's: said (it was
    # joined without a word; an audit, 2026-12)
    with pytest.warns(RuntimeWarning, match=r"its indices are of the accurate preset, these "
                                            r"elasticities of the paper preset \(.*; --preset "
                                            r"accurate gives elasticities of its model\)$"):
        assert studies_main(["elasticities", "--quick", "--no-progress", "--out", str(out),
                             "--gaits", GAIT, "--parameters", ",".join(PARAMETERS),
                             "--check", "alpha"]) == 0
    return out


@pytest.mark.slow
def test_the_table_has_a_row_per_parameter_and_its_plot(run):
    table = pd.read_csv(run / "elasticities.csv")
    assert list(table["parameter"]) == list(PARAMETERS)
    assert (table["gait"] == GAIT).all() and table["quick"].all()
    assert (run / "elasticities.png").stat().st_size > 0
    assert (run / "elasticities.csv.json").exists()


@pytest.mark.slow
def test_the_elasticity_is_p_over_v_times_the_derivative(run):
    table = pd.read_csv(run / "elasticities.csv")
    expected = table["value"] / table["signed_speed_mm_s"] * table["derivative"]
    # 1e-8: each of the three columns is written to 10 significant digits
    np.testing.assert_allclose(table["elasticity"], expected, rtol=1e-8)
    assert (table["elasticity"] != 0).sum() >= 3  # α, C⊥ and A1's gain move A1+A3
    at_zero = table[table["at_zero"]]
    assert list(at_zero["parameter"]) == ["damping_time"] and (at_zero["elasticity"] == 0).all()


@pytest.mark.slow
def test_an_idle_actuators_gain_has_no_effect_at_all(run):
    """A2 does not fire in A1+A3: its gain multiplies a curvature change that never comes, so
    its replicas' residuals equal the instance's and the derivative is exactly 0."""
    table = pd.read_csv(run / "elasticities.csv").set_index("parameter")
    assert not table.loc["actuator_gains[1]", "fired"]
    assert table.loc["actuator_gains[1]", "derivative"] == 0.0
    assert table.loc["actuator_gains[0]", "fired"]
    assert table.loc["actuator_gains[0]", "derivative"] != 0.0


@pytest.mark.slow
def test_the_sobol_columns_are_the_committed_sobol_cells(run):
    table = pd.read_csv(run / "elasticities.csv").set_index("parameter")
    sobol = pd.read_csv(cli.COMMITTED_RESULTS / "sensitivity.csv")
    for parameter in ("alpha", "drag_perpendicular", "damping_time"):
        (row,) = sobol[(sobol["gait"] == GAIT) & (sobol["parameter"] == parameter)].itertuples()
        for column in study.SOBOL_COLUMNS:
            assert table.loc[parameter, column] == pytest.approx(getattr(row, column), rel=1e-9)
    assert table.loc[["actuator_gains[0]", "actuator_gains[1]"], "ST"].isna().all()
    assert (table["sobol_preset"] == "accurate").all()  # from the Sobol table's sidecar


@pytest.mark.slow
def test_the_derivative_equals_a_whole_run_central_difference(run):
    check = pd.read_csv(run / "elasticities_check.csv")
    assert list(check["parameter"]) == ["alpha"]
    # 1e-5: the bound; the sensitivities are exact to ~1e-7-4e-6 for α
    # (docs/numerics.md), the extrapolated difference at h = 1e-4·α and Newton to 1e-12 m to
    # ~1e-6
    np.testing.assert_allclose(check["derivative"], check["finite_difference"], rtol=1e-5)
    table = pd.read_csv(run / "elasticities.csv").set_index("parameter")
    assert check["derivative"].iloc[0] == table.loc["alpha", "derivative"]


def test_the_check_differences_each_parameter_at_its_own_step(monkeypatch):
    """The whole-run differences take each parameter's step as `check_sensitivities` does: 1e-4
    of α, 1e-2 of C∥ and 1e-3 of the damping time (whose runs at 1e-4 differ by little more
    than their Newton noise), at h, 2h and 4h; the quotients are extrapolated from them."""
    from taichi_star import SolverConfig, StarParams

    params = [StarParams.preset("paper", gait=GAIT, damping_time=0.001)]
    fields = ("alpha", "drag_parallel", "damping_time")
    moved = []

    class Run:  # what the check reads of a simulate() result: the signed speed per instance
        def __init__(self, batch):
            moved.extend(batch)
            # a speed linear in each parameter's offset: every quotient is 1
            self.summary = pd.DataFrame({study.OUTPUT: [
                sum(getattr(q, f) - getattr(params[0], f) for f in fields) for q in batch]})

    # the moved runs are simulated by the library's `whole_run_differences`
    monkeypatch.setattr("taichi_star.sensitivity_check.simulate",
                        lambda batch, *args, **kwargs: Run(batch))
    check = study.finite_difference_check(params, fields, SolverConfig(), 0.1, "cpu")
    # 1e-9: the quotients of a linear speed are 1 up to the rounding of the offsets
    np.testing.assert_allclose(check["finite_difference"], 1.0, rtol=1e-9)
    for k, (field, relative) in enumerate(zip(fields, (1e-4, 1e-2, 1e-3))):
        value = getattr(params[0], field)
        offsets = [getattr(q, field) - value for q in moved[6 * k:6 * k + 6]]
        np.testing.assert_allclose(offsets, np.array([1, -1, 2, -2, 4, -4]) * relative * value,
                                   rtol=1e-9)


def test_default_parameters_leave_out_component_heights_at_zero():
    from taichi_star import StarParams

    paper = study.default_parameters(StarParams.preset("paper"))
    assert "hub_height" not in paper and "alpha" in paper and "linear_drag" in paper
    assert sorted(p for p in paper if "[" in p) == sorted(
        [f"actuator_gains[{k}]" for k in range(8)] + [f"actuator_delays[{k}]" for k in range(8)])
    tall = StarParams.preset("paper", hub_height=0.02, foam_height=0.02, actuator_height=0.02)
    assert {"hub_height", "foam_height", "actuator_height"} <= set(
        study.default_parameters(tall))


@pytest.mark.parametrize("flags, message", [
    (["--parameters", "hub_height"], "--parameters: hub_height is 0"),
    (["--parameters", "period"], "--parameters: sensitivities: 'period' is not differentiable"),
    (["--parameters", "alpah"], "did you mean alpha"),
    (["--parameters", "alpha", "--check", "cylinder_drag"],
     "--check: cylinder_drag is not among the parameters"),
    (["--parameters", "alpha,linear_drag", "--check", "linear_drag"],
     "--check: linear_drag is 0"),
    (["--sobol", "no_such.csv"], "--sobol: no such file"),
])
def test_bad_flags_fail_before_compute(no_compute, tmp_path, capsys, flags, message):
    assert studies_main(["elasticities", "--quick", "--out", str(tmp_path), *flags]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1
    assert not (tmp_path / "elasticities.csv").exists()


def test_all_names_every_differentiable_field_as_sensitivity_check_takes_it():
    """numerics.md quotes the all-terms run with --parameters all (it was refused: 'all' was
    not a field); it stands for every differentiable field, each per-actuator one as its
    eight actuators, in the field order the committed run's sidecar lists them, with the fields
    added since that run (the stroke's warming) in their places."""
    import json
    import shlex

    sidecar = cli.COMMITTED_RESULTS / "elasticities_all_terms" / "elasticities_all_terms.csv.json"
    words = shlex.split(json.loads(sidecar.read_text())["command"])
    listed = words[words.index("--parameters") + 1]
    labels = cli.sensitivity_parameters("all", "--parameters")
    added_since = ("stroke_warming", "cooling_time")
    assert [label for label in labels if label not in added_since] == \
        cli.sensitivity_parameters(listed, "--parameters")
    assert set(added_since) <= set(labels)
    assert len(labels) == 29 - 2 + 2 * 8  # the two per-actuator fields as eight labels each


def test_a_sobol_tables_actuator_elements_join_the_elasticities_of_the_same_actuator(tmp_path):
    """The sensitivity study names an element by its actuator's number (actuator_gains[1] is
    A1, as its --vary takes it), the elasticities by Python's index (actuator_gains[0]): the
    join put A1's indices on A2's row (an audit, 2026-12). Read through `sobol_table`, A1's
    row of the Sobol table is the elasticities' actuator_gains[0]; a scalar field keeps its
    name."""
    path = tmp_path / "sensitivity.csv"
    pd.DataFrame({"gait": ["A1", "A1"], "parameter": ["actuator_gains[1]", "alpha"],
                  "S1": [0.4, 0.2], "S1_conf": [0.01, 0.01], "ST": [0.5, 0.3],
                  "ST_conf": [0.02, 0.02]}).to_csv(path, index=False)
    table, preset = study.sobol_table(path)
    assert table["parameter"].tolist() == ["actuator_gains[0]", "alpha"] and preset == ""
    assert table["S1"].tolist() == [0.4, 0.2]
