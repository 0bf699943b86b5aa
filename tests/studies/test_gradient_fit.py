"""The gradient-fit study's arguments: every bad one refused before any simulation, one line
on stderr, exit code 2 (its numbers come from identification.objective_and_gradient, tested in
tests/unit/test_identification_gradient.py, and from the committed run in results/)."""

import pytest

from studies import gradient_fit
from studies.__main__ import main as studies_main


@pytest.mark.parametrize("argv, message", [
    (["--sets", "7"], "--sets: unknown value '7'"),
    (["--starts", "0"], "--starts must be >= 1"),
    (["--lbfgs-evaluations", "0"], "--lbfgs-evaluations must be >= 1"),
    (["--cma-generations", "0"], "--cma-generations must be >= 1"),
    (["--popsize", "1"], "--popsize must be >= 2"),
    (["--train-cycles", "0:3"], "--train-cycles: expected FIRST:LAST"),
    (["--train-cycles", "1:2", "--validate-cycles", "2:3"], "--validate-cycles 2:3: must start "
                                                             "after"),
    (["--validate-cycles", "4:40"], "shorter than cycles up to 40"),
    (["--gaits", "A1+A6"], "--gaits A1+A6: not measured"),
])
def test_invalid_arguments_fail_before_compute(no_compute, monkeypatch, tmp_path, capsys, argv,
                                               message):
    def forbidden(*args, **kwargs):
        raise AssertionError("simulate was called despite invalid arguments")
    monkeypatch.setattr(gradient_fit, "simulate", forbidden)
    assert studies_main(["gradient_fit", *argv, "--out", str(tmp_path), "--quick",
                         "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert message in error, error
    assert error.count("\n") == 1 and "Traceback" not in error


def test_the_twenty_parameter_set_extends_the_six():
    assert len(gradient_fit.PARAMETER_SETS["6"]) == 6
    assert len(gradient_fit.PARAMETER_SETS["20"]) == 20
    assert gradient_fit.PARAMETER_SETS["20"][:6] == gradient_fit.PARAMETER_SETS["6"]
