"""The parameters a study differentiates by (`cli.sensitivity_parameters`, elasticities'
--parameters and --check and sensitivity_check's --parameters): one rule for both studies, the
component heights in "all" as each study's robot has them."""

import pandas as pd
import pytest

from taichi_star import COMPONENT_HEIGHTS, DIFFERENTIABLE_FIELDS, PER_ACTUATOR_FIELDS

from studies import cli
from studies import sensitivity_check
from studies.__main__ import main as studies_main

HEIGHTS = ["hub_height", "foam_height", "actuator_height"]
ACTUATORS = 8


def test_a_list_is_taken_as_simulate_takes_it_whatever_the_heights():
    """Names as `simulate(sensitivities=...)` takes them, one label each: a per-actuator field
    stands for its eight actuators, one of them is named by its Python index; a height named
    is kept in every mode (elasticities refuses it later where it is 0)."""
    for heights in cli.HEIGHTS_IN_ALL:
        assert cli.sensitivity_parameters(" alpha , actuator_gains[2],hub_height", "--p",
                                          heights=heights) == \
            ["alpha", "actuator_gains[2]", "hub_height"]
    assert cli.sensitivity_parameters("actuator_delays", "--p") == \
        [f"actuator_delays[{k}]" for k in range(ACTUATORS)]


def test_all_is_every_differentiable_field_with_without_or_only_the_heights():
    every = cli.sensitivity_parameters("all", "--p")
    scalars = [name for name in DIFFERENTIABLE_FIELDS if name not in PER_ACTUATOR_FIELDS]
    # the library's order, the per-actuator fields last as their eight labels each
    assert every == scalars + [f"{field}[{k}]" for field in PER_ACTUATOR_FIELDS
                               for k in range(ACTUATORS)]
    assert len(every) == 29 - 2 + 2 * ACTUATORS and set(HEIGHTS) <= set(every)
    assert cli.sensitivity_parameters(" all ", "--p", heights="without") == \
        [label for label in every if label not in HEIGHTS]
    assert cli.sensitivity_parameters("all", "--p", heights="only") == HEIGHTS
    assert tuple(HEIGHTS) == COMPONENT_HEIGHTS
    with pytest.raises(ValueError, match=r"^heights must be one of \('with', 'without', "
                                         r"'only'\), got 'sideways'$"):
        cli.sensitivity_parameters("all", "--p", heights="sideways")


@pytest.mark.parametrize("text, message", [
    ("", "--parameters: empty value list"),
    ("alpha,,drag_parallel", "--parameters: malformed list 'alpha,,drag_parallel' (an empty "
                             "item)"),
    ("alpha, alpha", "--parameters: 'alpha' is listed twice in 'alpha, alpha' (give each value "
                     "once)"),
    # the same actuator by two names
    ("actuator_gains,actuator_gains[2]", "--parameters: sensitivities: 'actuator_gains[2]' is "
                                         "named twice"),
    ("alpah", "--parameters: sensitivities: 'alpah' is not a StarParams field; did you mean "
              "alpha?"),
    ("ALL", "--parameters: sensitivities: 'ALL' is not a StarParams field"),
    ("period", "--parameters: sensitivities: 'period' is not differentiable"),
    ("n_arc", "--parameters: sensitivities: 'n_arc' is not differentiable"),
    ("actuator_gains[8]", "--parameters: sensitivities: 'actuator_gains[8]' must name an "
                          "actuator index in [0, 7]"),
])
def test_a_bad_name_is_refused_naming_the_flag(text, message):
    with pytest.raises(cli.StudyArgumentError) as refused:
        cli.sensitivity_parameters(text, "--parameters")
    assert str(refused.value).startswith(message)


@pytest.mark.parametrize("argv, plain, tall", [
    # all: every field but the heights (off in the paper robot), the heights in their setting
    ([], "every differentiable label but the heights", HEIGHTS),
    # a list: the same in every setting
    (["--parameters", "alpha,actuator_gains[0]"], ["alpha", "actuator_gains[0]"],
     ["alpha", "actuator_gains[0]"]),
])
def test_sensitivity_check_differentiates_each_setting_by_its_parameters(no_compute, monkeypatch,
                                                                        tmp_path, argv, plain,
                                                                        tall):
    if isinstance(plain, str):
        plain = [label for label in cli.sensitivity_parameters("all", "--p")
                 if label not in HEIGHTS]
        assert len(plain) == 40
    checked = {}

    def check(params, duration_s, solver, names, progress=None):
        checked[(solver.integrator, solver.adaptive, params[0].damping_time,
                 params[0].hub_height)] = list(names)
        return pd.DataFrame({"parameter": list(names), "sensitivity": 1.0, "difference": 1.0,
                             "relative_error": 1e-8, "difference_spread": 1e-9,
                             "status": "ok"})
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", check)
    assert studies_main(["sensitivity_check", "--no-progress", "--gaits", "A1", "--out",
                         str(tmp_path), *argv]) == 0
    # the eight settings of the paper robot (its heights off), then the one with the heights
    assert [names for key, names in checked.items() if key[3] == 0.0] == [plain] * 8
    assert [names for key, names in checked.items() if key[3] > 0.0] == [tall]


def test_sensitivity_check_refuses_a_name_listed_twice_before_the_output_folder(no_compute,
                                                                                tmp_path,
                                                                                capsys):
    out = tmp_path / "out"
    assert studies_main(["sensitivity_check", "--parameters", "alpha,alpha", "--out",
                         str(out)]) == 2
    error = capsys.readouterr().err
    assert error.strip().endswith("error: --parameters: 'alpha' is listed twice in "
                                  "'alpha,alpha' (give each value once)")
    assert len(error.strip().splitlines()) == 1 and not out.exists()
