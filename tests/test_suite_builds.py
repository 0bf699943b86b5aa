"""tools/suite_builds.py's reading of pytest's last line and its alternating round order
(the suite runs themselves are what the tool measures, not tested here)."""

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def suite_builds():
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(REPO / "tools"))  # it imports bench_builds beside it
        spec = importlib.util.spec_from_file_location("suite_builds",
                                                      REPO / "tools" / "suite_builds.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("line, expected", [
    ("1241 passed, 5 skipped, 4 warnings in 236.09s (0:03:56)",
     {"pytest_s": 236.09, "passed": 1241, "failed": 0, "skipped": 5, "errors": 0}),
    ("2 failed, 1239 passed, 1 error in 12.5s",
     {"pytest_s": 12.5, "passed": 1239, "failed": 2, "skipped": 0, "errors": 1}),
])
def test_the_last_summary_line_gives_the_counts_and_seconds(suite_builds, line, expected):
    # a summary-like line earlier in the output (a test's own print) must not be taken
    output = f"3 passed in 1.0s\n........ [100%]\n{line}\n"
    assert suite_builds.last_line_figures(output) == expected


def test_the_failed_tests_are_named_from_the_short_summary(suite_builds):
    """Every run of the suite at 723010f and bff1951 on 2026-12-03 reported one failure that
    the table could not name (results/suite_time_since_stop61): FAILED and ERROR lines give
    the node ids, in order; a test whose own output mentions FAILED mid-line is not one."""
    output = ("..F.E [100%]\nsome test printed: FAILED to connect\n"
              "=== short test summary info ===\n"
              "FAILED tests/model/test_a.py::test_one[x-1] - AssertionError: 1 != 2\n"
              "ERROR tests/studies/test_b.py::test_two - RuntimeError: boom\n"
              "1 failed, 3 passed, 1 error in 2.0s\n")
    assert suite_builds.failed_tests(output) == \
        "tests/model/test_a.py::test_one[x-1] tests/studies/test_b.py::test_two"
    assert suite_builds.failed_tests("3 passed in 1.0s\n") == ""


def test_an_output_without_a_summary_line_is_refused(suite_builds):
    with pytest.raises(ValueError, match="no pytest summary line"):
        suite_builds.last_line_figures("collected 0 items\nINTERNALERROR\n")


def test_rounds_alternate_the_order_of_the_builds(suite_builds):
    builds = {"before": "a", "after": "b"}
    assert [suite_builds.round_order(builds, n) for n in (1, 2, 3)] == [
        ["before", "after"], ["after", "before"], ["before", "after"]]


def test_a_runs_output_goes_to_its_log_and_the_row_names_it(suite_builds, tmp_path, monkeypatch):
    """The log holds pytest's stdout then its stderr whole (the traceback of a failure that the
    row only names); the run had the tree on PYTHONPATH and a HOME of its own (an empty Taichi
    cache), gone after it."""
    stdout = ("F. [100%]\n___ test_x ___\nE   Failed: SIGINT handler SIG_IGN\n"
              "FAILED tests/test_x.py::test_x - Failed: SIGINT handler SIG_IGN\n"
              "1 failed, 1 passed in 3.5s\n")
    stderr = "a warning on stderr\n"
    seen = {}

    def fake_run(command, cwd, capture_output, text, env):
        seen.update(cwd=cwd, home=env["HOME"], pythonpath=env["PYTHONPATH"])
        assert Path(env["HOME"]).is_dir()
        return suite_builds.subprocess.CompletedProcess(command, 1, stdout, stderr)

    monkeypatch.setattr(suite_builds.subprocess, "run", fake_run)
    tree = tmp_path / "tree"
    row = suite_builds.run_suite(tree, tmp_path / "suite_after_round1.log")
    assert (tmp_path / "suite_after_round1.log").read_text() == stdout + stderr
    assert row["log"] == "suite_after_round1.log"
    assert (row["returncode"], row["passed"], row["failed"], row["failed_tests"]) == (
        1, 1, 1, "tests/test_x.py::test_x")
    assert seen["cwd"] == tree and seen["pythonpath"] == str(tree)
    assert seen["home"] != str(Path.home()) and not Path(seen["home"]).exists()
