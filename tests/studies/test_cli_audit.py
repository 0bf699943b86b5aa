"""Study-specific flags refused on the command line before any compute and before the output
folder is made: one line naming the flag and its range, exit code 2, no traceback (each case
crashed with a traceback, started work that could not finish, or refused only after making the
output folder)."""

import pytest

from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]
STEP_LIMIT = "the limit is 2147483647 steps per instance"


@pytest.mark.parametrize("study, argv, message", [
    ("bench", ["--plain-duration", "0"], "--plain-duration must be in [0.001, 100] s, got 0.0"),
    ("bench", ["--sensitivity-duration", "nan"], "--sensitivity-duration must be in [0.001, 100]"),
    ("convergence", ["--n-arc", "500,1000,2000"], "--n-arc: n_arc must be an integer in [2, 1000]"),
    ("env_bench", ["--control-period", "1e12"], "--control-period 1e+12 s (2e+12 s) at --dt"),
    ("env_bench", ["--steps", "1000000000"], "--steps 1000000000 (+1 compiling)"),
    ("gait_design", ["--direction", "nan"], "--direction must be a finite angle (deg), got nan"),
    ("gait_design", ["--seed", "-1"], "--seed must be >= 0, got -1"),
    # --quick runs whole --cycles here, not --quick's 0.2 s
    ("gait_design", ["--cycles", "1000000000"], "--cycles 1000000000 (3.15e+09 s)"),
    ("plan", ["--max-cycles", "1000000000"], "--max-cycles 1000000000 + --settle-cycles 1"),
    ("plan", ["--glide-cycles", "1000000000"], "--cycles 2 + --glide-cycles 1000000000"),
    ("primitives", ["--glide-cycles", "1000000000"], "--cycles 2 + --glide-cycles 1000000000"),
    ("calibrate", ["--restarts", "11"], "--restarts must be <= 10"),
    ("model_select", ["--restarts", "1000000"], "--restarts must be <= 10"),
    ("gradient_fit", ["--seed", "-1"], "--seed must be >= 0, got -1"),
    ("sensitivity_check", ["--parameters", "bogus"], "--parameters: sensitivities: 'bogus'"),
    ("sensitivity_check", ["--duration", "1e12"], "--duration 1e+12 s at --dt 0.001 s"),
    ("sensitivity_check", ["--duration", "1e-9"], "--duration 1e-09 s is less than one step"),
    ("simd", ["--matmul-size", "10000000"], "--matmul-size must be in [16, 8192], got 10000000"),
    ("sweep", ["--max-instances", "0"], "--max-instances must be >= 1, got 0"),
])
def test_study_flags_are_refused_before_the_output_folder(no_compute, tmp_path, capsys, study,
                                                          argv, message):
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert "Traceback" not in error
    assert not out.exists()


def test_the_step_limit_is_named_with_the_estimate(no_compute, tmp_path, capsys):
    assert studies_main(["primitives", "--cycles", "1000000000", "--out", str(tmp_path / "out"),
                         *QUICK]) == 2
    error = capsys.readouterr().err
    assert "6.3e+11 time steps per instance" in error and STEP_LIMIT in error, error


def test_gait_design_refuses_a_table_that_is_not_primitives(no_compute, tmp_path, capsys):
    table = tmp_path / "other.csv"
    table.write_text("gait,speed\nA1,1.0\n")
    out = tmp_path / "out"
    assert studies_main(["gait_design", "--primitives", str(table), "--out", str(out),
                         *QUICK]) == 2
    error = capsys.readouterr().err
    assert "--primitives" in error and "not a primitives table" in error, error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


def test_model_select_resume_needs_out(no_compute, tmp_path, monkeypatch, capsys):
    """model_select keeps its finished candidates in --out itself: it has no --run-dir."""
    monkeypatch.chdir(tmp_path)
    assert studies_main(["model_select", "--resume", *QUICK]) == 2
    error = capsys.readouterr().err
    assert "--resume: give --out (the folder of the run to continue)" in error, error
    assert "--run-dir" not in error and not any(tmp_path.iterdir())
