"""`python -m studies sensitivity_check` around its check (`check_sensitivities` replaced by
fakes): the work of every setting checked before anything runs, the table written after each
setting, --no-progress passed on, compute errors let through, and a summary and plot that
count every row, failed ones and exactly zero differences included."""

import numpy as np
import pandas as pd
import pytest

from studies import cli, sensitivity_check
from studies.__main__ import main as studies_main


@pytest.fixture
def forbidden_check(no_compute, monkeypatch):
    """The check itself fails the test, in the study and in the library (whose `simulate`
    `no_compute` does not reach): a refusal must come before it."""
    def forbidden(*args, **kwargs):
        raise AssertionError("the check ran despite invalid arguments")
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", forbidden)
    monkeypatch.setattr("taichi_star.sensitivity_check.simulate", forbidden)


def check_table(names, **columns):
    """A table with check_sensitivities' columns, one row per name: a well-conditioned check
    unless `columns` (each a value or one per row) say otherwise."""
    table = pd.DataFrame({"instance": 0, "gait": "A1", "parameter": list(names), "value": 0.8,
                          "output": "displacement_x_mm", "sensitivity": 2.0,
                          "difference_h": 2.0, "difference_2h": 2.0, "difference_4h": 2.0,
                          "difference": 2.0, "absolute_error": 2e-10, "relative_error": 1e-10,
                          "difference_spread": 1e-9, "taylor_ratio": 4.0, "status": "ok",
                          "failure_time_s": np.nan})
    return table.assign(**columns)


def test_the_work_of_every_setting_together_is_refused_before_the_output_folder(
        forbidden_check, tmp_path, capsys):
    """2e6 s is 2e9 steps, within one instance's counter, but 6,478 instance-runs of them
    (two gaits, forty parameters in eight settings and three heights in the ninth) are 1.3e13
    robot-steps, past the 9.3e12 that no machine measured finishes in 30 days."""
    out = tmp_path / "out"
    assert studies_main(["sensitivity_check", "--duration", "2000000", "--out", str(out)]) == 2
    error = capsys.readouterr().err
    assert "error: --duration 2e+06 s (6,478 instance-runs in 9 settings) is " \
           "1.3e+13 robot-steps" in error
    assert not out.exists()


def test_a_long_study_is_estimated_before_anything_runs(no_compute, monkeypatch, tmp_path):
    """1e4 s: 1e7 steps × 6,478 instance-runs, 6.5e10 robot-steps, past the 1e10 that warn
    with the hours (each setting's 802 or 62 instance-runs alone, 8.0e9 at most, would not)."""
    def stop(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", stop)
    with pytest.warns(RuntimeWarning) as told:
        assert studies_main(["sensitivity_check", "--duration", "10000", "--out",
                             str(tmp_path)]) == 130
    assert [str(w.message).split(" robot-steps")[0] for w in told] == [
        "--duration 10000 s (6,478 instance-runs in 9 settings) is 6.48e+10"]


@pytest.mark.parametrize("stop, code", [(KeyboardInterrupt, 130), (ValueError, None)])
def test_a_run_stopped_in_a_later_setting_keeps_the_settings_before(no_compute, monkeypatch,
                                                                    tmp_path, stop, code):
    """A kill (exit 130) or a fault of the second setting (a ValueError: raised as it is, not
    an argument error's exit 2 after the first had run) leaves the first setting's rows."""
    done = []

    def check(params, duration_s, solver, names, progress=None):
        if done:
            raise stop("in the second setting")
        done.append(solver)
        return check_table(names)
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", check)
    argv = ["sensitivity_check", "--no-progress", "--gaits", "A1", "--parameters", "alpha",
            "--out", str(tmp_path)]
    if code is None:
        with pytest.raises(ValueError, match="in the second setting"):
            studies_main(argv)
    else:
        assert studies_main(argv) == code
    table = pd.read_csv(tmp_path / "sensitivity_check.csv")
    assert list(table["setting"]) == ["euler/undamped/fixed"]
    assert list(table["parameter"]) == ["alpha"]


@pytest.mark.parametrize("flags, progress", [(["--no-progress"], False), ([], True)])
def test_no_progress_reaches_every_check(no_compute, monkeypatch, tmp_path, capsys, flags,
                                         progress):
    told = []

    def check(params, duration_s, solver, names, **options):
        told.append(options.get("progress", "not passed"))
        return check_table(names)
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", check)
    assert studies_main(["sensitivity_check", *flags, "--gaits", "A1", "--parameters", "alpha",
                         "--out", str(tmp_path)]) == 0
    assert told == [progress] * 9


def test_a_height_listed_is_refused_naming_the_flag_and_the_setting_that_sets_heights(
        forbidden_check, tmp_path, capsys):
    """A list is checked in every setting; a height has a derivative only where the 2.5-D
    model is on, in the heights setting alone: refused before the output folder, not by the
    first setting's run."""
    out = tmp_path / "out"
    assert studies_main(["sensitivity_check", "--parameters", "hub_height", "--out",
                         str(out)]) == 2
    error = capsys.readouterr().err.strip()
    assert error.endswith(
        "error: --parameters: in setting euler/undamped/fixed: sensitivities: hub_height is 0 "
        "(the 2.5-D model off) for instance 0; its derivative is defined only with the "
        "component heights set (> 0); a --parameters list is checked in every setting, and "
        "only euler/heights/fixed (not run with --quick) sets the component heights: "
        "--parameters all checks them there")
    assert len(error.splitlines()) == 1 and not out.exists()


def test_the_summary_and_the_plot_count_failed_rows_and_zero_differences(
        no_compute, monkeypatch, tmp_path, capsys):
    """One row of each kind: well-conditioned, ill-conditioned (spread 1e-3), differences and
    sensitivity exactly 0 (relative error and spread NaN), differences exactly 0 under a
    sensitivity of 0.5 (relative error inf: a failure of the check) and a failed run (NaN).
    Before, the summary counted the last three nowhere and the plot dropped them silently."""
    names = ["alpha", "drag_parallel", "actuator_gains[6]", "actuator_gains[7]", "thickness"]
    nan = np.nan

    def check(params, duration_s, solver, names, progress=None):
        return check_table(
            names, sensitivity=[2.0, 2.0, 0.0, 0.5, nan],
            difference=[2.0, 2.0, 0.0, 0.0, nan], absolute_error=[2e-10, 2e-4, 0.0, 0.5, nan],
            relative_error=[1e-10, 1e-4, nan, np.inf, nan],
            difference_spread=[1e-9, 1e-3, nan, nan, nan],
            status=["ok"] * 4 + ["newton_failed"], failure_time_s=[nan] * 4 + [0.012])
    monkeypatch.setattr(sensitivity_check, "check_sensitivities", check)
    titles = []
    save_figure = cli.save_figure

    def saved(fig, png_path, **options):
        titles.append(fig.axes[0].get_title())
        return save_figure(fig, png_path, **options)
    monkeypatch.setattr(cli, "save_figure", saved)
    assert studies_main(["sensitivity_check", "--quick", "--no-progress", "--gaits", "A1",
                         "--parameters", ",".join(names), "--out", str(tmp_path)]) == 0
    assert capsys.readouterr().out.strip().splitlines()[-1] == (
        "all settings: 5 checks: 1 well-conditioned (spread <= 1e-06), relative error max "
        "1e-10, median 1e-10; 1 ill-conditioned; 1 with differences and sensitivity exactly 0; "
        "failed: 1 with differences exactly 0 but a sensitivity not, 1 whose runs did not "
        "finish ok")
    assert titles[0].splitlines()[-1] == (
        "2 of 5 checks drawn; not drawn: 1 failed runs, 1 non-zero sensitivities at zero "
        "differences, 1 zero at zero, 0 with an error or spread of 0")
