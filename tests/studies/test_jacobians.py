"""The Jacobian modes study: its --quick run against direct simulations, the error bound it
states, and its argument checks (the whole run's work among them)."""

import warnings

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams, timegrid
from taichi_star.experiment import PAPER_GAITS

from studies import cli, jacobians
from studies.__main__ import main as studies_main


def test_quick_run_measures_each_mode_against_the_reference(tmp_path):
    table = jacobians.main(["--quick", "--out", str(tmp_path), "--no-progress"])
    written = pd.read_csv(tmp_path / "jacobians.csv")
    assert written["jacobian"].tolist() == ["newton", "lagged", "newton"]
    assert written["reference"].tolist() == [False, False, True]
    default, lagged, reference = (written.iloc[i] for i in range(3))
    # the reference against itself, and the default against itself
    assert reference["position_error_m"] == 0.0 and default["same_bits_as_default"]
    # the study's figures are those of a direct run: 5 instances, 0.05 s of 1-ms steps
    params = [StarParams(gait=PAPER_GAITS[i % 5]) for i in range(5)]
    direct = {tol: taichi_star.simulate(params, 0.05, SolverConfig(jacobian="lagged",
                                                                   newton_tol=tol))
              for tol in (1e-10, 1e-13)}
    # the CSV keeps 10 significant digits of the same mean of the same bits (a result does
    # not depend on its batch): exactly the direct run's
    assert lagged["factorisations_mean"] == float(
        f"{direct[1e-10].summary['factorisations_mean'].mean():.10g}")
    assert default["steps"] == 50 and default["error_bound_m"] == float(f"{50 * 1e-10:.10g}")
    # the lagged run differs from the reference by at most the bound newton_tol sets (each
    # step's error left at most newton_tol, the errors adding at worst), but by more than
    # round-off: another path to the steps' solutions, not Newton's bits
    assert 1e-13 < lagged["position_error_m"] <= lagged["error_bound_m"]
    assert not lagged["same_bits_as_default"]
    assert lagged["factorisations_mean"] < default["factorisations_mean"]
    # the speedups were divided before the CSV rounded them and the times to 10 digits: three
    # roundings of at most 5e-10 (relative) each, 1.5e-9 at worst (1e-9 could fail)
    np.testing.assert_allclose(written["speedup_vs_default"],
                               written["wall_s"].iloc[0] / written["wall_s"], rtol=2e-9)
    assert len(table) == 3 and (tmp_path / "jacobians.png").stat().st_size > 1000


def test_the_default_and_the_reference_are_always_run_once():
    assert jacobians.parse_modes("lagged:1e-11,newton:1e-10,lagged:1e-11") == [
        ("newton", 1e-10), ("lagged", 1e-11), ("newton", 1e-13)]


@pytest.mark.parametrize("argv, flag", [
    (["--modes", "lagged"], "--modes"),               # no tolerance
    (["--modes", "secant:1e-10"], "--modes"),         # no such mode
    (["--modes", "lagged:1e-3"], "--modes"),          # tolerance out of range
    (["--batch", "0"], "--batch"),
    (["--rounds", "0"], "--rounds"),
    (["--duration", "0.0001"], "--duration"),
])
def test_bad_arguments_are_one_line_errors_before_any_compute(no_compute, argv, flag,
                                                              tmp_path, capsys):
    out = tmp_path / "out"
    assert studies_main(["jacobians", *argv, "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and flag in error
    assert not out.exists()  # refused before the output folder is made


def test_quick_never_writes_into_the_committed_results():
    with pytest.raises(cli.StudyArgumentError, match="--quick"):
        jacobians.main(["--quick", "--out", str(cli.COMMITTED_RESULTS)])


class PastTheChecks(Exception):
    """The study got past its checks to the stubbed building of the batch."""


def past_the_checks(*args, **kwargs):
    raise PastTheChecks


def test_the_whole_runs_hours_are_told_before_the_batch_is_built(no_compute, monkeypatch,
                                                                 tmp_path):
    """--batch 65536 --duration 100 --rounds 1 simulates 3.9e10 robot-steps in six
    configurations (the five default modes and the reference), one call of 6.6e9 at a time,
    each under the warning: it started without a word (an audit, 2026-12). Each configuration
    runs --duration at 1 ms once per round after a one-step warm-up."""
    monkeypatch.setattr(cli, "paper_gaits_batch", past_the_checks)
    robot_steps = 65536 * 6 * (100_000 + 1)
    with warnings.catch_warnings(record=True) as caught, pytest.raises(PastTheChecks):
        warnings.simplefilter("always")
        studies_main(["jacobians", "--batch", "65536", "--duration", "100", "--rounds", "1",
                      "--out", str(tmp_path / "out")])
    assert [str(w.message) for w in caught if w.category is taichi_star.LongWorkWarning] == [
        f"--batch 65536 × 6 configurations × (--rounds 1 of --duration 100 s + a one-step "
        f"warm-up) is {robot_steps:.3g} robot-steps: about {robot_steps / 5e4 / 3600:.3g} h at "
        f"50000 robot-steps/s (on a 2-core CPU; a GPU or more cores run faster)"]


QUICK_RUN = ("--batch 5 × 3 configurations × (--rounds 2 of --duration 0.05 s + a one-step "
             "warm-up)")


@pytest.mark.parametrize("limit, value, refused, told", [
    ("REFUSE_ROBOT_STEPS", 1514, True, False), ("REFUSE_ROBOT_STEPS", 1515, False, False),
    ("WARN_ROBOT_STEPS", 1514, False, True), ("WARN_ROBOT_STEPS", 1515, False, False)])
def test_the_rounds_and_configurations_robot_steps_are_added_up(no_compute, monkeypatch,
                                                                 tmp_path, checked_run, limit,
                                                                 value, refused, told):
    """--quick's 5 instances in 3 configurations (newton and lagged at 1e-10 m, the
    reference), 2 rounds of 50 steps and a warm-up step each: 5 × 3 × (2 × 50 + 1) = 1,515
    robot-steps, refused or told past a limit of 1,514, not at 1,515 (the rule is "over")."""
    stub, run = checked_run
    monkeypatch.setattr(timegrid, limit, value)
    monkeypatch.setattr(cli, "paper_gaits_batch", stub)
    error, said = run(["jacobians", "--quick", "--rounds", "2", "--out",
                       str(tmp_path / "out")], refused)
    assert (f"error: {QUICK_RUN} is 1.52e+03 robot-steps: about " in error) == refused, error
    assert said == ([f"{QUICK_RUN} is 1.52e+03 robot-steps: about {1515 / 5e4 / 3600:.3g} h at "
                     f"50000 robot-steps/s (on a 2-core CPU; a GPU or more cores run faster)"]
                    if told else [])
