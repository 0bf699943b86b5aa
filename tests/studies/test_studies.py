"""The studies on the command line: every study in --quick mode into tmp_path with its values
checked against a direct `simulate` of the same instances, argument and output-folder errors
before any compute, provenance sidecars, the gait-symmetry basis of the gaits study, and the
packaged experiment data."""

import hashlib
import json
import os
import re
import shlex
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import SolverConfig, StarParams
from taichi_star import metrics, provenance
from taichi_star.gait import Gait, symmetry_classes
from taichi_star.params import PER_ACTUATOR_FIELDS, parameter_column
from taichi_star.primitives import (class_symmetries, transform_direction,
                                    transform_rotation)
from taichi_star.experiment import (FIG4C_COLUMNS, PAPER_GAITS)

from studies import (cli, gaits as gaits_study, provenance as study_provenance, reproduce,
                     study_names)
from studies.cli import COMMITTED_RESULTS
from studies.__main__ import main as studies_main, program as main_program

QUICK = ["--quick", "--no-progress"]
QUICK_SOLVER = SolverConfig(dt=cli.QUICK_DT)


def quick_simulation(params):
    """What a --quick study simulates for these instances, run directly."""
    return taichi_star.simulate(params, cli.QUICK_DURATION_S, QUICK_SOLVER)


def as_csv_keeps(values) -> np.ndarray:
    """`values` as a study's CSV gives them back: 10 significant digits (`cli.Output.write_csv`;
    a decimal of 10 digits reads back as its nearest double). The study runs the instances the
    direct call runs, and a result does not depend on its batch (test_determinism): the CSV's
    numbers are these exactly, not within a tolerance."""
    return np.array([float(f"{value:.10g}") for value in np.asarray(values, dtype=float)])


def pngs_written(*paths):
    for path in paths:
        assert path.exists() and path.stat().st_size > 1000, path


# ----------------------------------------------------------------------------- argument parsing

def test_parse_values_and_ranges():
    assert cli.parse_values("0.2:1.2:11", "--alpha") == pytest.approx(
        [0.2 + 0.1 * i for i in range(11)])
    assert cli.parse_values("0,0.5,1", "--added-mass") == [0.0, 0.5, 1.0]
    assert cli.parse_values("1e6:1e8:3:log", "--youngs-modulus") == pytest.approx([1e6, 1e7, 1e8])
    assert cli.parse_values("contract,always", "--jet-mode", str) == ["contract", "always"]
    for bad in ("0.2:1.2", "a:1:3", "0:1:x", "0:1:0", "1,,2", "1:2:3:lin", "nan"):
        with pytest.raises(cli.StudyArgumentError, match="--alpha"):
            cli.parse_values(bad, "--alpha")


def test_an_integer_field_takes_a_range_whose_every_value_is_an_integer():
    """sweep --param n_arc=10:20:3 was refused as "not an integer" (the range form was read as
    one number); a range of integers is taken when it lands on integers, exact ints, and one
    that does not is refused naming the first value that is not one (a comma list stays)."""
    assert cli.parse_values("10:20:3", "--param n_arc", int) == [10, 15, 20]
    assert all(type(v) is int for v in cli.parse_values("10:20:3", "--param n_arc", int))
    assert cli.parse_values("7:7:1", "--param n_arc", int) == [7]
    assert cli.parse_values("2:128:7:log", "--param n_arc", int) == [2, 4, 8, 16, 32, 64, 128]
    assert cli.parse_values("10,15", "--param n_arc", int) == [10, 15]
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^--param n_arc: the range '10:20:4' gives 13.3333, not an "):
        cli.parse_values("10:20:4", "--param n_arc", int)
    with pytest.raises(cli.StudyArgumentError, match="malformed range"):
        cli.parse_values("10:20", "--param n_arc", int)
    # a large range's half-integer is no integer (1e-9 of the magnitude let it pass)
    with pytest.raises(cli.StudyArgumentError, match="gives 1000000001.5, not an integer"):
        cli.parse_values("1000000000:1000000003:3", "--param n_arc", int)
    assert cli.parse_counts("64:4096:7:log", "--batch-sizes") == [64, 128, 256, 512, 1024,
                                                                    2048, 4096]


def test_param_product_order_and_validation():
    grid = cli.param_product({"gait": ["A1", "A1+A2"], "alpha": [0.5, 1.0]})
    assert [(p.gait, p.alpha) for p in grid] == [("A1", 0.5), ("A1", 1.0), ("A1+A2", 0.5),
                                                 ("A1+A2", 1.0)]
    with pytest.raises(cli.StudyArgumentError, match="unknown parameter 'beta'"):
        cli.param_product({"beta": [1.0]})
    with pytest.raises(cli.StudyArgumentError, match="empty product"):
        cli.param_product({"alpha": []})
    with pytest.raises(cli.StudyArgumentError, match="^alpha: alpha must be"):
        cli.param_product({"alpha": [-1.0]})
    with pytest.raises(cli.StudyArgumentError, match="^--alpha: alpha must be"):
        cli.param_product({"alpha": [-1.0]}, flags={"alpha": "--alpha"})


def test_values_that_fit_only_with_other_swept_values_are_left_to_the_combinations():
    """A value the base model refuses but the other axes' values take is swept, not refused on
    its own (a tip radius inside the base's joint radius, beyond the swept one; one of three
    component heights, all set together; an audit, 2026-12); one no first value rescues is
    refused on its own, naming its flag."""
    grid = cli.param_product({"joint_radius": [0.02], "tip_radius": [0.021, 0.03]})
    assert [(p.joint_radius, p.tip_radius) for p in grid] == [(0.02, 0.021), (0.02, 0.03)]
    heights = cli.param_product({"hub_height": [0.01], "foam_height": [0.01, 0.02],
                                 "actuator_height": [0.01]})
    assert [(p.hub_height, p.foam_height, p.actuator_height) for p in heights] == [
        (0.01, 0.01, 0.01), (0.01, 0.02, 0.01)]
    # inside the base's joint radius and the swept one's too: refused alone, by its flag, with
    # the range the swept joint radius gives (the base's, (0.024, 2], was named: a review)
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^--tip: tip_radius must be .* in \(0\.02, 2\] .* got 0\.019"):
        cli.param_product({"joint_radius": [0.02], "tip_radius": [0.019]},
                          flags={"tip_radius": "--tip"})
    # fits the first swept value, not the second: the combination is refused, naming both
    with pytest.raises(cli.StudyArgumentError, match="joint_radius, tip_radius together"):
        cli.param_product({"joint_radius": [0.02, 0.025], "tip_radius": [0.021]})


def test_quick_defaults_and_presets():
    parser = cli.StudyParser("probe", "a test parser")
    parser.add_argument("--frames", type=int, default=60, quick=5, help="frames")
    cli.add_model_flags(parser, fixed=("gait",))
    cli.add_dt_flag(parser)
    assert cli.parse(parser, []).frames == 60
    assert cli.parse(parser, ["--quick"]).frames == 5
    assert cli.parse(parser, ["--quick", "--frames", "60"]).frames == 60  # given beats quick
    args = cli.parse(parser, ["--preset", "accurate", "--set", "alpha=1.0"])
    assert cli.base_params(args) == StarParams.preset("accurate", alpha=1.0)
    assert cli.solver(args) == SolverConfig.preset("accurate")
    assert cli.solver(cli.parse(parser, ["--quick"])).dt == cli.QUICK_DT
    # --jacobian changes the preset's mode and nothing else; without it the preset's stays
    assert cli.solver(cli.parse(parser, ["--preset", "accurate", "--jacobian", "lagged"])) == \
        SolverConfig.preset("accurate", jacobian="lagged")
    assert cli.solver(cli.parse(parser, [])).jacobian == SolverConfig.preset("paper").jacobian
    with pytest.raises(cli.StudyArgumentError, match="--set gait: set by the probe study"):
        cli.base_params(cli.parse(parser, ["--set", "gait=A1"]))
    # a per-actuator field: its eight values A1..A8 are the one value; seven are refused, as is
    # a value out of its range, each naming the field
    delays = cli.base_params(cli.parse(parser, ["--set", "actuator_delays=0,0.1,0,0,0,0,0,0.5"]))
    assert delays.actuator_delays == (0.0, 0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5)
    # delays beyond the preset's period fit a swept one: taken on top of the first swept value
    late = ["--set", "actuator_delays=0,0,0,0,0,0,0,4"]
    with pytest.raises(cli.StudyArgumentError, match=r"^--set: actuator_delays\[7\]"):
        cli.base_params(cli.parse(parser, late))
    swept = cli.base_params(cli.parse(parser, late), {"period": [5.0, 6.0]})
    assert swept.period == 5.0 and swept.actuator_delays[7] == 4.0
    with pytest.raises(cli.StudyArgumentError, match=r"^--set: actuator_delays\[7\]"):
        cli.base_params(cli.parse(parser, late), {"period": [3.5, 5.0]})
    # only the swept values the --set needs are the base's (all of them were recorded, and a
    # bad one among them blamed the --set: a review, 2026-12); the bad one is its flag's
    axes = {"gait": ["A3", "A1"], "alpha": [-1.0, 1.0], "period": [5.0, 6.0]}
    needed = cli.base_params(cli.parse(parser, late), axes)
    assert needed == StarParams.preset("paper", period=5.0,
                                       actuator_delays=(0, 0, 0, 0, 0, 0, 0, 4.0))
    with pytest.raises(cli.StudyArgumentError, match=r"^--alpha: alpha must be"):
        cli.check_axis_values(axes, needed, {"alpha": "--alpha"})
    with pytest.raises(cli.StudyArgumentError, match="actuator_gains must have 8 entries"):
        cli.base_params(cli.parse(parser, ["--set", "actuator_gains=1,1,1,1,1,1,1"]))
    with pytest.raises(cli.StudyArgumentError, match=r"actuator_gains\[2\] \(A3\) must be"):
        cli.base_params(cli.parse(parser, ["--set", "actuator_gains=1,1,-1,1,1,1,1,1"]))
    with pytest.raises(cli.StudyArgumentError, match="--set actuator_gains: 'x' is not a number"):
        cli.base_params(cli.parse(parser, ["--set", "actuator_gains=1,1,x,1,1,1,1,1"]))


@pytest.mark.parametrize("study, argv, message", [
    ("sweep", ["--alpha", "0.2:1.2"], "--alpha: malformed range"),
    ("sweep", ["--alpha", "0.2:1.2:zero"], "--alpha: malformed range"),
    ("sweep", ["--param", "beta=1,2"], "unknown parameter 'beta'"),
    ("sweep", ["--gaits", ""], "empty"),
    ("sweep", ["--alpha", ""], "empty"),
    ("sweep", ["--gaits", "A1,A9"], "unknown actuator 'A9'"),
    ("sweep", ["--alpha=-1,1"], "alpha must be"),
    ("sweep", ["--jet-mode", "sometimes"], "jet_mode must be one of"),
    ("fig4c", ["--set", "gamma=1"], "--set: unknown parameter 'gamma'"),
    ("fig4c", ["--set", "alpa=1"], "--set: unknown parameter 'alpa'; did you mean alpha?"),
    ("fig4c", ["--set", "alpha"], "--set: expected NAME=VALUE (e.g. alpha=0.8), got 'alpha'"),
    ("sweep", ["--param", "alpha"], "--param: expected NAME=VALUES (e.g. alpha=0.2:1.2:6)"),
    ("fig4c", ["--set", "alpha=1,2"], "exactly one value"),
    ("fig4c", ["--set", "gait=A1"], "--set gait"),
    # both ends of the step's range named (a zero step was told "> 0" alone)
    ("fig4c", ["--dt", "0.5"], "--dt must be in (0, 0.05] s, got 0.5"),
    ("fig4c", ["--dt", "0"], "--dt must be in (0, 0.05] s, got 0.0"),
    # the value as given: a hair past the end was shown rounded onto it (an audit, 2026-12)
    ("fig4c", ["--dt", "0.05000001"], "--dt must be in (0, 0.05] s, got 0.05000001"),
    # --quick runs 0.2 s instead of the cycles: a --cycles given with it was ignored
    ("fig4c", ["--cycles", "2"], "--cycles: not with --quick, which simulates a short time"),
    ("work_precision", ["--cycles", "2"], "--cycles: not with --quick"),
    ("fig4c", ["--cycles", "nan"], "--cycles must be > 0"),
    ("fig4c", ["--prefix", "../../escape"], "--prefix: '../../escape' is not a file name"),
    ("fig4c", ["--prefix", "sub/fig"], "--prefix: 'sub/fig' is not a file name"),
    ("fig4c", ["--prefix", ".."], "--prefix: '..' is not a file name"),
    ("fig4c", ["--prefix", ""], "--prefix: '' is not a file name"),
    # identification (calibrate, sensitivity): more cases in test_identify.py
    ("calibrate", ["--fit", "alpha=1:2:3"], "--fit alpha: malformed bounds"),
    ("calibrate", ["--fit", "jet_mode=0:1"], "--fit jet_mode: not a real-valued numeric field"),
    ("sensitivity", ["--vary", "alpha=0.2"], "--vary alpha: malformed bounds"),
    ("gaits", ["--cycles", "0"], "--cycles must be > 0"),
    ("animate", ["--gait", "A0"], "--gait"),
    ("animate", ["--frames", "1"], "--frames must be in [2, 10000], got 1"),
    ("convergence", ["--n-arc", "18,30,60"], "--n-arc"),
    ("convergence", ["--n-arc", "18,36"], "--n-arc"),
    ("scaling", ["--workers-list", "0"], "--workers-list"),
])
def test_invalid_arguments_fail_before_compute(no_compute, tmp_path, capsys, study, argv,
                                               message):
    out = tmp_path / "out"
    code = studies_main([study, *argv, "--out", str(out), *QUICK])
    assert code == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert not out.exists()  # nothing written


def test_the_cycles_and_the_step_are_taken_where_they_are_meant():
    """The allowed sides of the refusals above: --cycles without --quick, the default under
    --quick, --cycles with --quick where --quick runs the cycles (strokes: it was told that
    --quick simulates 0.2 s, which it does not), and the longest step."""
    from studies import fig4c, strokes

    assert cli.parse(fig4c.build_parser(), ["--cycles", "2"]).cycles == 2
    assert cli.parse(fig4c.build_parser(), ["--quick"]).cycles == 3
    assert cli.parse(strokes.build_parser(), ["--quick", "--cycles", "4"]).cycles == 4
    assert "--quick simulates" not in strokes.build_parser().format_help()
    assert cli.parse(fig4c.build_parser(), ["--dt", "0.05"]).dt == 0.05


def test_resume_needs_the_folder_of_the_run(no_compute, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert studies_main(["sweep", "--resume", *QUICK]) == 2
    assert "--resume: give --out" in capsys.readouterr().err
    assert not any(tmp_path.iterdir())


def test_the_jacobian_flag_reaches_the_run_and_its_provenance(tmp_path):
    """fig4c --jacobian lagged: the speeds of the lagged call made directly, and the mode in
    the table's sidecar."""
    from studies import fig4c
    fig4c.main([*QUICK, "--jacobian", "lagged", "--out", str(tmp_path)])
    table = pd.read_csv(tmp_path / "fig4c.csv")
    direct = taichi_star.simulate([StarParams(gait=g) for g in PAPER_GAITS],
                                  cli.QUICK_DURATION_S,
                                  QUICK_SOLVER.replace(jacobian="lagged")).summary
    np.testing.assert_array_equal(table["sim_speed_mm_s"], as_csv_keeps(direct["speed_mm_s"]))
    sidecar = json.loads((tmp_path / "fig4c.csv.json").read_text())
    assert sidecar["solver"]["jacobian"] == "lagged"


def test_a_study_that_times_several_jacobian_modes_has_no_jacobian_flag(capsys):
    assert studies_main(["env_bench", "--jacobian", "lagged", "--quick"]) == 2
    assert "unrecognized arguments: --jacobian" in capsys.readouterr().err


def test_unknown_study_and_unknown_flag(no_compute, capsys):
    assert studies_main(["fig4d"]) == 2
    assert "unknown study 'fig4d'" in capsys.readouterr().err
    assert studies_main(["sweep", "--betta", "1"]) == 2
    assert "unrecognized arguments: --betta" in capsys.readouterr().err


def test_every_study_has_help(capsys):
    for name in study_names():
        assert studies_main([name, "--help"]) == 0
        assert f"python -m studies {name}" in capsys.readouterr().out


# ----------------------------------------------------------------------------- output folders

@pytest.mark.parametrize("target, message", [
    ("/proc/taichi_star_out", "cannot create it"),
    ("a_file", "exists and is not a folder"),
])
def test_bad_output_folder_fails_before_compute(no_compute, tmp_path, capsys, target, message):
    (tmp_path / "a_file").write_text("mine")
    out = target if target.startswith("/") else str(tmp_path / target)
    assert studies_main(["fig4c", "--out", out, *QUICK]) == 2
    error = capsys.readouterr().err
    assert f"--out {out}: {message}" in error and len(error.strip().splitlines()) == 1
    assert (tmp_path / "a_file").read_text() == "mine"


def test_a_default_output_folder_that_cannot_be_made_is_named_as_the_default(no_compute,
                                                                            capsys, monkeypatch):
    """Run from a folder where runs/ cannot be made (a read-only checkout), the refusal named
    `--out`, which the user had not given (an audit, 2026-12): it names the default folder,
    where it is, and --out."""
    monkeypatch.chdir("/proc")
    assert studies_main(["fig4c", *QUICK]) == 2
    error = capsys.readouterr().err.strip()
    assert re.search(r"error: the default output folder runs/fig4c/\S+ \(under /proc; --out DIR "
                     r"names another\): cannot create it \(", error), error
    assert len(error.splitlines()) == 1


def test_an_unwritable_output_folder_fails_before_compute(no_compute, tmp_path, capsys,
                                                          monkeypatch):
    """Whoever runs it (root writes into a read-only folder): the probe file that
    check_output_folder makes in the folder is refused as the kernel refuses it, EACCES."""
    folder = tmp_path / "locked"
    folder.mkdir()
    probe = cli.tempfile.TemporaryFile

    def refused_in_the_folder(*args, **kwargs):
        if Path(kwargs.get("dir", "")) == folder:
            raise PermissionError(13, "Permission denied")
        return probe(*args, **kwargs)

    monkeypatch.setattr(cli.tempfile, "TemporaryFile", refused_in_the_folder)
    assert studies_main(["fig4c", "--out", str(folder), *QUICK]) == 2
    error = capsys.readouterr().err
    assert error == (f"python -m studies fig4c: error: --out {folder}: not writable "
                     f"(Permission denied)\n"), error
    assert not any(folder.iterdir())


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_read_only_output_folder_fails_before_compute(no_compute, tmp_path, capsys):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        assert studies_main(["fig4c", "--out", str(folder), *QUICK]) == 2
        assert "not writable" in capsys.readouterr().err
    finally:
        folder.chmod(0o755)


@pytest.mark.parametrize("inside", ["", "paper_dt5", "a/new/folder", "paper_dt5/../fig4c_q"])
def test_quick_never_writes_into_the_committed_results(no_compute, capsys, inside):
    """Neither results/ itself nor any folder under it, existing or not, spelt with `..` or
    not; the folder is not created."""
    out = cli.COMMITTED_RESULTS / inside
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 2
    assert "never write into the committed results/" in capsys.readouterr().err
    assert not (cli.COMMITTED_RESULTS / "a").exists()
    assert not (cli.COMMITTED_RESULTS / "fig4c_q").exists()


def test_quick_may_write_beside_the_committed_results(no_compute, tmp_path, monkeypatch):
    """A sibling whose name only starts like it ("results_quick") is not inside it."""
    monkeypatch.setattr(cli, "COMMITTED_RESULTS", tmp_path / "results")
    cli.check_output_folder(tmp_path / "results_quick", quick=True)
    assert (tmp_path / "results_quick").is_dir()


def test_the_launcher_says_its_version(capsys):
    assert studies_main(["--version"]) == 0
    assert capsys.readouterr().out == f"taichi_star {taichi_star.__version__}\n"


def test_a_reader_that_leaves_ends_the_study_quietly(capfd, monkeypatch):
    """`python -m studies fig4c | head -1`: the pipe breaks while the table prints; exit code 1
    and no traceback, and stdout is pointed at /dev/null so that its flush at exit cannot
    fail either."""
    from studies import fig4c

    def printing_into_a_closed_pipe(argv):
        raise BrokenPipeError(32, "Broken pipe")

    monkeypatch.setattr(fig4c, "main", printing_into_a_closed_pipe)
    saved = os.dup(1)
    try:
        assert studies_main(["fig4c"]) == 1
        print("after")          # goes to /dev/null now
    finally:
        os.dup2(saved, 1)
        os.close(saved)
    out, err = capfd.readouterr()
    assert "after" not in out and "Traceback" not in err


def test_a_fault_in_a_study_keeps_its_traceback_and_leaves_no_empty_folder(tmp_path,
                                                                           monkeypatch):
    """A study that fails on its own fault (not on bad input) shows its traceback, and the
    output folder the run made is removed while still empty (an audit, 2026-12: it stayed);
    one the run had written into, or one that was there before, is kept."""
    from studies import fig4c

    made, written, there = tmp_path / "made", tmp_path / "written", tmp_path / "there"
    there.mkdir()

    def failing(argv):
        for folder in (made, written, there):
            out = cli.Output(SimpleNamespace(study="fig4c", out=str(folder), quick=False), argv)
            if folder is written:
                out.path("table.csv").write_text("a\n")
        raise ZeroDivisionError("a fault of the study")

    monkeypatch.setattr(fig4c, "main", failing)
    with pytest.raises(ZeroDivisionError, match="a fault of the study"):
        studies_main(["fig4c"])
    assert not made.exists()
    assert (written / "table.csv").exists() and there.is_dir()


def test_reproduce_lists_one_command_per_committed_result(capsys):
    assert studies_main(["reproduce", "--dry-run", "--into", "elsewhere"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[0] == "python -m studies fig4c --no-progress --out elsewhere"
    assert all("--quick" not in line for line in lines)
    assert any(line.startswith("python -m studies fig4c --preset accurate") for line in lines)


def test_reproduce_elsewhere_gives_elasticities_the_sobol_table_it_made(capsys, tmp_path):
    """Into another folder, elasticities read the committed Sobol table, not the one the same
    run had just made there (and outside a checkout, which has none, failed after hours of the
    others: a review, 2026-12); without that run's sensitivity, or into results/, the flags
    are as committed."""
    into = tmp_path / "into"
    # in the results' order whatever --only's (elasticities first read the committed table)
    assert studies_main(["reproduce", "--dry-run", "--into", str(into), "--only",
                         "elasticities,sensitivity,elasticities_accurate"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert [line.split()[3] for line in lines] == ["sensitivity", "elasticities", "elasticities"]
    assert [f"--sobol {into / 'sensitivity.csv'}" in line for line in lines] == [False, True, True]
    for argv in (["--into", str(into), "--only", "elasticities"],
                 ["--only", "sensitivity,elasticities"]):
        assert studies_main(["reproduce", "--dry-run", *argv]) == 0
        assert "--sobol" not in capsys.readouterr().out


SIDECAR_OF = {"calibrate": "calibration"}
"""The committed table of a reproduce entry named otherwise."""


def _run_flags(command):
    """A study command's words without where it wrote (--out, --run-dir) and --no-progress."""
    words, kept = shlex.split(command), []
    while words:
        word = words.pop(0)
        if word in ("--out", "--run-dir"):
            words.pop(0)
        elif word != "--no-progress":
            kept.append(word)
    return kept


@pytest.mark.parametrize("name", [n for n in cli.REPRODUCED_RESULTS if n != "animate"])
def test_reproduce_runs_each_committed_result_as_its_sidecar_says_it_was_made(name):
    """`reproduce` regenerates what the docs quote only if it runs each study with the flags
    of the committed run (its elasticities check once named 2 of the 11 parameters whose
    cells the docs quote). `animate` writes animations, which carry no sidecar."""
    sidecar = COMMITTED_RESULTS / f"{SIDECAR_OF.get(name, name)}.csv.json"
    made_with = json.loads(sidecar.read_text())["command"]
    assert _run_flags(" ".join(reproduce.command(name, Path("x"))[1:])) == \
        _run_flags(made_with.removeprefix("python "))


# ----------------------------------------------------------------------------- studies, quick

def test_fig4c_quick_into_a_fresh_run_folder(tmp_path, monkeypatch):
    from studies import fig4c
    monkeypatch.chdir(tmp_path)
    started = time.monotonic() - study_provenance.STARTED
    fig4c.main(QUICK)
    finished = time.monotonic() - study_provenance.STARTED
    (folder,) = (tmp_path / "runs" / "fig4c").iterdir()  # runs/fig4c/<timestamp>/
    table = pd.read_csv(folder / "fig4c.csv")
    assert list(table.columns) == FIG4C_COLUMNS
    direct = quick_simulation([StarParams(gait=g) for g in PAPER_GAITS]).summary
    assert table["gait"].tolist() == list(PAPER_GAITS)
    np.testing.assert_array_equal(table["sim_speed_mm_s"], as_csv_keeps(direct["speed_mm_s"]))
    np.testing.assert_array_equal(table["sim_signed_speed_mm_s"],
                                  as_csv_keeps(direct["signed_speed_mm_s"]))
    assert table["exp_speed_mm_s"].tolist() == pytest.approx([0.428, 2.85, 3.37, 3.349, 2.748])
    summary = pd.read_csv(folder / "fig4c_summary.csv")
    assert summary["newton_iterations_max"].tolist() == direct["newton_iterations_max"].tolist()
    curves = pd.read_csv(folder / "fig4b.csv")
    assert set(curves["source"]) == {"simulation", "experiment"}
    simulated = curves[curves["source"] == "simulation"]
    assert simulated["t_s"].max() == pytest.approx(cli.QUICK_DURATION_S)
    final = simulated.groupby("gait", sort=False)["displacement_mm"].last()
    np.testing.assert_array_equal(final[list(PAPER_GAITS)], as_csv_keeps(
        np.hypot(direct["displacement_x_mm"], direct["displacement_y_mm"])))
    pngs_written(folder / "fig4c.png", folder / "fig4b.png")
    sidecar = json.loads((folder / "fig4c.csv.json").read_text())
    for key in ("taichi_star_version", "git_commit", "git_dirty", "model", "solver", "command",
                "taichi_version", "library_versions", "machine", "date"):
        assert key in sidecar, key
    assert sidecar["taichi_star_version"] == taichi_star.__version__
    # the study's wall time when it wrote the table, counted from the study's start (in a test
    # process: the module's import; rounded to 0.1 s)
    assert started - 0.05 <= sidecar["elapsed_s"] <= finished + 0.05
    # the table it describes, by content: read_provenance checks it
    assert sidecar["table_sha256"] == hashlib.sha256((folder / "fig4c.csv").read_bytes()).hexdigest()
    assert sidecar["table_rows"] == len(table)
    assert sidecar["command"] == "python -m studies fig4c --quick --no-progress"
    assert sidecar["model"]["preset"] == "paper" and sidecar["solver"]["dt"] == cli.QUICK_DT
    assert sidecar["model"]["params"]["alpha"] == StarParams().alpha
    assert {"cpu_model", "cores", "gpus"} <= set(sidecar["machine"])
    # the unit of every parameter column and of every metric with a unit suffix
    units = json.loads((folder / "fig4c_summary.csv.json").read_text())["units"]
    numeric = [column for name, column in StarParams.columns().items()
               if isinstance(getattr(StarParams(), name), (int, float))]
    assert set(numeric) <= set(units)
    assert (units["youngs_modulus_pa"], units["period_s"], units["speed_mm_s"],
            units["heading_deg"]) == ("Pa", "s", "mm/s", "degree")


def test_sweep_quick(tmp_path):
    from studies import sweep
    sweep.main(["--out", str(tmp_path), "--alpha", "0.4:1.2:3", "--jet-mode", "contract,always",
                "--gaits", "A1,A1+A3", *QUICK])
    table = pd.read_csv(tmp_path / "sweep.csv")
    grid = cli.param_product({"gait": ["A1", "A1+A3"], "alpha": [0.4, 0.8, 1.2],
                              "jet_mode": ["contract", "always"]})
    assert table["instance"].tolist() == list(range(len(grid)))
    assert [(g, a, j) for g, a, j in zip(table.gait, table.alpha, table.jet_mode)] == \
        [(p.gait, p.alpha, p.jet_mode) for p in grid]
    direct = quick_simulation(grid).summary
    for column in ("speed_mm_s", "signed_speed_mm_s", "heading_deg", "newton_iterations_mean"):
        np.testing.assert_array_equal(table[column], as_csv_keeps(direct[column]), column)
    pngs_written(tmp_path / "sweep_alpha.png", tmp_path / "sweep_jet_mode.png")
    assert json.loads((tmp_path / "sweep.csv.json").read_text())["details"]["axes"]["alpha"] \
        == pytest.approx([0.4, 0.8, 1.2])
    # the Parquet copy: the library's floats bit for bit, typed columns, provenance inside
    parquet = pd.read_parquet(tmp_path / "sweep.parquet")
    np.testing.assert_array_equal(parquet["signed_speed_mm_s"], direct["signed_speed_mm_s"])
    assert parquet["status"].tolist() == table["status"].tolist()
    import pyarrow.parquet as pq
    inside = json.loads(pq.read_schema(tmp_path / "sweep.parquet").metadata[b"taichi_star"])
    assert inside["details"]["axes"]["jet_mode"] == ["contract", "always"]
    # plot titles and axes say how the table was made and in which units
    assert cli.run_settings(tmp_path / "sweep.csv") == \
        f"paper preset, n_arc 18, euler h = {1e3 * cli.QUICK_DT:g} ms"
    assert cli.run_settings(tmp_path / "sweep.csv", mesh=False) == \
        f"paper preset, euler h = {1e3 * cli.QUICK_DT:g} ms"
    assert (cli.axis_label("period_s"), cli.axis_label("alpha"), cli.axis_label("speed_mm_s")) \
        == ("period (s)", "alpha", "speed_mm_s (mm/s)")


def test_sweep_quick_with_sensitivities(tmp_path, monkeypatch):
    """--sensitivities: each row of the sweep's table carries its instance's derivatives,
    simulate's to the CSV's digits and bit for bit in the Parquet copy; the work told counts
    the replicas; the sidecar names the parameters."""
    from studies import sweep
    names = ["alpha", "actuator_gains[0]"]
    sweep.main(["--out", str(tmp_path), "--alpha", "0.4,1.2", "--gaits", "A1+A3",
                "--sensitivities", ",".join(names), *QUICK])
    grid = cli.param_product({"gait": ["A1+A3"], "alpha": [0.4, 1.2]})
    direct = taichi_star.simulate(grid, cli.QUICK_DURATION_S, QUICK_SOLVER, sensitivities=names)
    table = pd.read_csv(tmp_path / "sweep.csv")
    parquet = pd.read_parquet(tmp_path / "sweep.parquet")
    derivatives = [column for column in table if column.startswith("d(")]
    assert derivatives == direct.sensitivities.columns.tolist() and len(derivatives) == 16
    assert (direct.sensitivities["d(displacement_x_mm)/d(alpha)"].abs() > 1e-6).all()
    for column in derivatives:
        np.testing.assert_array_equal(table[column], as_csv_keeps(direct.sensitivities[column]))
        np.testing.assert_array_equal(parquet[column], direct.sensitivities[column])
    np.testing.assert_array_equal(table["speed_mm_s"], as_csv_keeps(direct.summary["speed_mm_s"]))
    assert json.loads((tmp_path / "sweep.csv.json").read_text())["details"]["sensitivities"] \
        == names
    arguments = cli.parse(sweep.build_parser(), ["--gaits", "A1+A3", *QUICK])
    # 5 instances' work per robot: itself and a pair per parameter, and the warning says so
    from taichi_star import timegrid
    monkeypatch.setattr(timegrid, "WARN_ROBOT_STEPS", 0)
    with pytest.warns(taichi_star.LongWorkWarning) as told:
        assert cli.tell_batch_work(arguments, QUICK_SOLVER, 2, replicas=5) \
            == 5 * cli.tell_batch_work(arguments, QUICK_SOLVER, 2)
    assert [str(w.message).split(" is ")[0] for w in told] == [
        "the batch of 2 instances (--quick (0.2 s), each simulated 5 times over for its "
        "sensitivities)", "the batch of 2 instances (--quick (0.2 s))"]


@pytest.mark.parametrize("with_slopes", [True, False])
def test_a_sweeps_plot_draws_each_points_exact_slope_where_the_table_has_it(monkeypatch,
                                                                            tmp_path,
                                                                            with_slopes):
    """A sweep table with the speeds' derivatives by its swept parameter (--sensitivities):
    each ok point of both panels carries a segment through it of that slope, 0.3 of the
    nearest spacing each side, in its gait's colour, and the title says so; a failed point,
    and a table without them, none."""
    from studies import sweep
    table = pd.DataFrame({
        "gait": "A1", "alpha": [0.4, 0.8, 1.2, 1.6], "status": ["ok", "ok", "ok", "diverged"],
        "speed_mm_s": [1.0, 2.0, 4.0, 5.0], "signed_speed_mm_s": [1.0, -2.0, -4.0, -5.0],
        "duration_s": 0.2})
    slopes = {"speed_mm_s": [2.5, 3.75, 5.0, 1.0], "signed_speed_mm_s": [-2.5, -3.75, -5.0, -1.0]}
    if with_slopes:
        for column, values in slopes.items():
            table[f"d({column})/d(alpha)"] = values
    table.to_csv(tmp_path / "sweep.csv", index=False)
    drawn = []
    monkeypatch.setattr(cli, "write_figure", lambda fig, path, **kw: drawn.append(fig))
    sweep.plot_sweep(tmp_path / "sweep.csv", SimpleNamespace(path=lambda name: tmp_path / name))
    (fig,) = drawn
    assert fig.texts[0].get_text().endswith("short lines: exact slopes") is with_slopes
    for ax, column in zip(fig.axes, slopes):
        curve = ax.lines[0]
        segments = [line for line in ax.lines if line.get_alpha() == 0.5]
        assert len(segments) == (3 if with_slopes else 0)
        for k, segment in enumerate(segments):
            (x0, x1), (y0, y1) = segment.get_xdata(), segment.get_ydata()
            assert (x0 + x1) / 2 == pytest.approx(table["alpha"][k])
            assert x1 - x0 == pytest.approx(2 * 0.3 * 0.4)
            assert (y1 - y0) / (x1 - x0) == pytest.approx(slopes[column][k])
            assert (y0 + y1) / 2 == pytest.approx(table[column][k])
            assert segment.get_color() == curve.get_color()


def test_gaits_quick(tmp_path):
    gaits_study.main(["--out", str(tmp_path), *QUICK])
    table = pd.read_csv(tmp_path / "gaits.csv")
    assert list(table.columns) == gaits_study.GAITS_COLUMNS
    assert len(table) == 255 and table["gait"].is_unique
    assert table["class_representative"].nunique() == 29
    assert table.groupby("class_representative")["class_size"].first().sum() == 255
    classes = pd.read_csv(tmp_path / "gaits_classes.csv")
    assert len(classes) == 29
    # three classes simulated directly: same speeds, every member of a class the same
    representatives = classes["gait"].tolist()[::12]
    direct = quick_simulation([StarParams(gait=g) for g in representatives]).summary
    for gait, speed in zip(representatives, direct["speed_mm_s"]):
        members = table[table["class_representative"] == gait]
        assert (members["speed_mm_s"] == as_csv_keeps([speed])[0]).all(), gait
    pngs_written(tmp_path / "gaits.png")


def test_animate_quick(tmp_path):
    from PIL import Image
    from studies import animate
    animate.main(["--out", str(tmp_path), "--frames", "5", *QUICK])
    folder = tmp_path / "animations"
    with Image.open(folder / "A1_A2.gif") as gif:
        assert gif.n_frames >= 5
    shapes = pd.read_csv(folder / "shapes.csv")
    assert list(shapes.columns) == ["gait", "frame", "t_s", "node", "x_mm", "y_mm"]
    last = shapes[shapes["frame"] == shapes["frame"].max()].sort_values("node")
    direct = taichi_star.simulate([StarParams(gait="A1+A2")], cli.QUICK_DURATION_S, QUICK_SOLVER,
                                  record_interval_s=cli.QUICK_DURATION_S, record_shapes=True)
    assert last[["x_mm", "y_mm"]].to_numpy() == pytest.approx(1e3 * direct.shapes[-1, 0],
                                                              abs=1e-5)
    edges = pd.read_csv(folder / "edges.csv")
    assert len(edges) == direct.topology.n_edges and set(edges["actuator"]) == set(range(9))
    assert sorted(map(tuple, np.sort(edges[["node_a", "node_b"]].to_numpy(), axis=1))) == \
        sorted(map(tuple, np.sort(direct.topology.edges, axis=1)))


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
    # the images differ by the rounding of their turned meshes, carried through 100 Newton
    # solves that each stop at their own residual under newton_tol = 1e-10 m: at worst 1e-8 m
    # of drift, 1.5e-5 of the 0.65-mm displacement; Newton's last iterate lands far below its
    # tolerance, and the runs agree to 7e-11 (speeds), 8e-10° (direction), 2e-11° (heading).
    # 1e-6 of the displacement (speeds; 1e-6 rad = 6e-5°, rounded up to 1e-4°, direction)
    # leaves 1e4 for round-off and still fails a wrong image, another gait at the percent
    # level; the heading, a 0.05° turn, within 1e-9° (60x its round-off). The speeds are
    # > 1 mm/s: no absolute part.
    assert np.allclose(speed, speed[0], rtol=1e-6, atol=0)
    assert np.allclose(summary["signed_speed_mm_s"], summary["signed_speed_mm_s"].iloc[0],
                       rtol=1e-6, atol=0)
    travel = summary["travel_direction_deg"]
    for (rotation, reflect), direction, heading in zip(images, travel, summary["heading_deg"]):
        expected = transform_direction(travel.iloc[0], rotation, reflect)
        assert abs(metrics.wrap_degrees(direction - expected)) < 1e-4
        assert heading == pytest.approx(
            transform_rotation(summary["heading_deg"].iloc[0], reflect), abs=1e-9)
    # and the class expansion agrees with these direct simulations
    rep_class = next(c for c in symmetry_classes() if source in c[1])
    assert set(gaits) <= set(rep_class[1])
    sources = class_symmetries()
    for gait, direction in zip(gaits, travel):
        representative, *mapping, _ = sources[gait]
        assert representative == source
        assert Gait.parse(source).transform(*mapping).name == gait
        assert abs(metrics.wrap_degrees(
            transform_direction(travel.iloc[0], *mapping) - direction)) < 1e-4


def test_a_study_csv_keeps_the_parameters_exact_and_rounds_the_other_floats(tmp_path):
    """Every float was written to 10 digits, so `StarParams.from_row` of a study's row was not
    the robot simulated (an audit): the parameter columns are exact (the shortest text that
    reads back to the float, an empty cell for NaN), the other floats keep 10 digits (a rerun
    on another CPU differs only where the results do)."""
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    robot = StarParams(alpha=0.1234567890123, youngs_modulus=5e6 + 1e-3)
    # a summary's row: the profile and the per-actuator tuples as text, as `simulate` writes
    row = {column: getattr(robot, name) for name, column in StarParams.columns().items()}
    row.update({parameter_column(name): str(getattr(robot, name)) for name in PER_ACTUATOR_FIELDS},
               actuator_profile=robot.actuator_profile.to_text(), speed_mm_s=0.1234567890123,
               steady_speed_mm_s=np.nan)
    row = pd.DataFrame([row])
    text = out.write_csv(row, "table.csv").read_text()
    assert ",0.1234567890123," in text and ",0.123456789," in text
    back = pd.read_csv(tmp_path / "table.csv")
    assert back["alpha"][0] == robot.alpha and back["youngs_modulus_pa"][0] == 5e6 + 1e-3
    assert np.isnan(back["steady_speed_mm_s"][0])
    assert StarParams.from_row(back.iloc[0]) == robot


def test_remove_earlier_takes_a_table_and_its_sidecar_and_names_what_it_cannot(tmp_path):
    """`Output.remove_earlier` removes an earlier run's table with its sidecar and a plot,
    passes over a file that is not there, and names the file it cannot remove (a folder of
    that name here) in a StudyOutputError, leaving the others."""
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    for name in ("old.csv", "old.csv.json", "old.png", "kept.csv"):
        (tmp_path / name).write_text("an earlier run's\n")
    out.remove_earlier("old.csv", "old.png", "never_written.csv")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["kept.csv"]
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(cli.StudyOutputError, match=r"cannot remove the earlier run's folder\.csv "
                                                   r"\(.*\); the files written before are intact$"):
        out.remove_earlier("folder.csv")
    assert (tmp_path / "kept.csv").read_text() == "an earlier run's\n"


def test_a_command_line_the_locale_could_not_decode_is_recorded_as_valid_text():
    """Under LANG=C a non-ASCII path reached sys.argv as lone surrogates, which no PNG text
    entry (a study's figure failed with a traceback) and no strict JSON reader takes (an
    audit, 2026-12): its bytes are recorded as UTF-8 text, or as escapes where they are none."""
    import json

    undecoded = "/tmp/r\udcc3\udca9sum\udcc3\udca9"  # b"/tmp/résumé" under LANG=C
    assert study_provenance.shown_argv(["--out", undecoded]) == "--out '/tmp/résumé'"
    assert study_provenance.shown_argv(["a\udcff b"]) == "'a\\xff b'"  # not UTF-8: an escape
    command = study_provenance.record("fig4c", ["--out", undecoded])["command"]
    assert command == "python -m studies fig4c --out '/tmp/résumé'"
    json.dumps(command).encode("utf-8")  # no lone surrogate left


def test_a_study_figure_names_the_study_command_and_commit_in_its_png(tmp_path):
    """A study's PNG carried nothing of what made it (an audit): its text entries name the
    study and command of the process's run (`provenance.record`), and the code version."""
    from PIL import Image

    cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False),
               ["--quick", "--out", "x y"])
    plt = cli.use_agg()
    fig, ax = plt.subplots()
    path = cli.save_figure(fig, tmp_path / "f.png", dpi=30)
    code = provenance.code_version()
    with Image.open(path) as image:
        entries = dict(image.text)
    assert {key: entries[key] for key in ("study", "command", "git_commit", "git_dirty",
                                          "taichi_star_version")} == {
        "study": "fig4c", "command": "python -m studies fig4c --quick --out 'x y'",
        "git_commit": code["commit"] or "unknown",
        "git_dirty": {True: "true", False: "false", None: "unknown"}[code["dirty"]],
        "taichi_star_version": taichi_star.__version__}
    assert entries.get("git_changes_sha256") == code.get("changes_sha256")


def test_a_failed_table_write_leaves_the_previous_table_and_sidecar(tmp_path, monkeypatch):
    """A study's table and sidecar are written whole or not at all: a write that fails (a full
    disk at the rename) leaves the previous table and its provenance readable and equal."""
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    first = pd.DataFrame({"alpha": [0.4, 0.8], "speed_mm_s": [1.25, 2.5]})
    path = out.write_csv(first, "table.csv")
    sidecar = (tmp_path / "table.csv.json").read_text()

    def full_disk(source, target):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(provenance.os, "replace", full_disk)
    with pytest.raises(cli.StudyOutputError, match=f"--out {tmp_path}: cannot write table.csv "
                                                    f"\\(No space left on device\\)"):
        out.write_csv(pd.DataFrame({"alpha": [0.1], "speed_mm_s": [9.0]}), "table.csv")
    pd.testing.assert_frame_equal(pd.read_csv(path), first)
    assert (tmp_path / "table.csv.json").read_text() == sidecar
    assert sorted(p.name for p in tmp_path.iterdir()) == ["table.csv", "table.csv.json"]


def test_a_failed_figure_write_leaves_the_previous_figure_and_names_the_file(tmp_path,
                                                                              monkeypatch):
    """matplotlib wrote a study's PNG into the file itself: a full disk left a truncated
    picture over the previous one and an OSError naming no file, under "the files written
    before are intact" (an audit, 2026-12). Written whole or not at all, the error names it."""
    plt = cli.use_agg()
    fig, ax = plt.subplots()
    ax.plot([0, 1], [0, 1])
    path = cli.write_figure(fig, tmp_path / "speeds.png", dpi=50)
    before = path.read_bytes()
    assert before.startswith(b"\x89PNG")
    assert plt.fignum_exists(fig.number)  # written: its caller closes it

    def full_disk(source, target):
        raise OSError(28, os.strerror(28))
    monkeypatch.setattr(provenance.os, "replace", full_disk)
    ax.plot([0, 1], [1, 0])
    with pytest.raises(cli.StudyOutputError, match=r"cannot write speeds.png \(No space left on "
                                                   r"device\); the files written before are "
                                                   r"intact"):
        cli.write_figure(fig, path, dpi=80)
    assert not plt.fignum_exists(fig.number)  # closed: a caller catching the error keeps none
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["speeds.png"]


def test_ctrl_c_is_one_line_saying_what_is_kept(tmp_path, monkeypatch, capsys):
    """Ctrl-C printed the traceback of wherever the run was (35 lines, an audit) and left the
    folder the run had made. Now: one line, exit 130 (a shell's for SIGINT), the run's empty
    folder removed; a study with a run store names its finished chunks and --resume."""
    def interrupt(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr("studies.figures.run_fig4c", interrupt)
    out = tmp_path / "fig4c"
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 130
    error = capsys.readouterr().err
    assert error == (f"{main_program()} fig4c: interrupted; the files written before are "
                     f"whole\n")
    assert not out.exists()

    def interrupt_after(chunks):
        def run_batch(*args, run_dir, **kwargs):
            Path(run_dir).mkdir(parents=True)
            for index in range(chunks):
                (Path(run_dir) / f"chunk_{index:06d}.parquet").write_bytes(b"")
            raise KeyboardInterrupt
        return run_batch
    # interrupted before the first chunk ended: the store holds no chunk to resume from (it
    # said it did, an audit)
    monkeypatch.setattr("studies.sweep.run_batch", interrupt_after(0))
    assert studies_main(["sweep", "--out", str(tmp_path / "first"), *QUICK]) == 130
    assert capsys.readouterr().err.endswith("interrupted; the files written before are whole\n")
    monkeypatch.setattr("studies.sweep.run_batch", interrupt_after(1))
    out = tmp_path / "sweep"
    assert studies_main(["sweep", "--out", str(out), *QUICK]) == 130
    error = capsys.readouterr().err
    assert error == (f"{main_program()} sweep: interrupted; the finished chunks in "
                     f"{out / 'chunks'} are kept: the same command with --resume continues "
                     f"the run\n")
    # model_select keeps its finished candidates in done/ (it said only that the files were
    # whole: an audit, 2026-12); before the first is done there is nothing to resume from
    out = tmp_path / "model_select"

    def interrupt_with_records(records):
        def fit_candidate(*args, **kwargs):
            for name in records:
                (out / "done").mkdir(parents=True, exist_ok=True)
                (out / "done" / f"{name}.json").write_text("{}")
            raise KeyboardInterrupt
        return fit_candidate
    monkeypatch.setattr("studies.model_select.fit_candidate", interrupt_with_records([]))
    assert studies_main(["model_select", "--out", str(out), *QUICK]) == 130
    assert capsys.readouterr().err.endswith("interrupted; the files written before are whole\n")
    monkeypatch.setattr("studies.model_select.fit_candidate", interrupt_with_records(["paper"]))
    assert studies_main(["model_select", "--out", str(out), *QUICK]) == 130
    assert capsys.readouterr().err == (f"{main_program()} model_select: interrupted; the "
                                       f"finished work in {out / 'done'} is kept: the same "
                                       f"command with --resume continues the run\n")


def test_sigterm_is_one_line_saying_what_is_kept(tmp_path, monkeypatch, capsys):
    """SIGTERM (`kill`, a scheduler's stop) ended a study at once with Python's default
    handler: the run's empty folder and a run store's lock stayed (an audit, 2026-12). Now it
    takes Ctrl-C's way out with its own word and a shell's status for it (128 + 15); a real
    signal, sent to this process mid-study."""
    import signal

    slept_out = []

    def killed(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(30)  # the handler raises as soon as the signal arrives, ending the sleep
        slept_out.append(True)  # not reached: the sleep was cut short
    monkeypatch.setattr("studies.figures.run_fig4c", killed)
    out = tmp_path / "fig4c"
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 143
    assert not slept_out
    assert capsys.readouterr().err == (f"{main_program()} fig4c: terminated; the files "
                                       f"written before are whole\n")
    assert not out.exists()
    # the default handler is back once the study has ended (a later SIGTERM ends the process)
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL


def test_a_sweeps_long_work_is_one_line_told_before_its_million_instances_are_built(tmp_path):
    """A sweep of a million instances (1000 × 200 values, five gaits) for four cycles (of
    3.15 s at 1-ms steps: 12,600 steps each) is 1.26e10 robot-steps, past the warning's 1e10:
    told in one line as the errors are, the study's name first (Python's two lines of file
    and source until 2026-12), and at once, before the instances are built
    (about two minutes, after which run_batch told it, an audit). The run is then stopped
    with SIGTERM while it builds them."""
    import signal
    import subprocess
    import sys

    out = tmp_path / "sweep"
    process = subprocess.Popen(
        [sys.executable, "-m", "studies", "sweep", "--alpha", "0.2:1.2:1000", "--added-mass",
         "0:1:200", "--cycles", "4", "--out", str(out)],
        cwd=Path(__file__).resolve().parents[2], stderr=subprocess.PIPE, text=True)
    try:
        first = process.stderr.readline()
    finally:
        process.send_signal(signal.SIGTERM)
        rest = process.communicate(timeout=120)[1]
    hours = 1_000_000 * 12_600 / 5e4 / 3600
    assert first == (f"python -m studies sweep: warning: the batch of 1,000,000 instances "
                     f"(--cycles 4 of its period) is 1.26e+10 robot-steps: about {hours:.3g} h "
                     f"at 50000 robot-steps/s (on a 2-core CPU; a GPU or more cores run "
                     f"faster)\n")
    assert rest == "python -m studies sweep: terminated; the files written before are whole\n"
    assert process.returncode == 143 and not out.exists()


def test_only_the_librarys_runtime_warnings_are_one_line_in_a_study(tmp_path, monkeypatch):
    """Within a study a RuntimeWarning prints as one line naming the study; another category
    (a library's deprecation) keeps Python's format, which says where it came from; and after
    the study the format is Python's again."""
    import warnings
    import studies.__main__ as entry

    python_format = warnings.formatwarning
    shown = {}

    def formats(*args, **kwargs):
        shown["runtime"] = warnings.formatwarning("slow", RuntimeWarning, "x.py", 3, "line")
        shown["long"] = warnings.formatwarning("slow", taichi_star.LongWorkWarning, "x.py", 3)
        shown["deprecation"] = warnings.formatwarning("old", DeprecationWarning, "x.py", 3, "")
        raise KeyboardInterrupt  # the study stops here: its format was what this test asks
    monkeypatch.setattr("studies.figures.run_fig4c", formats)
    assert entry.main(["fig4c", "--out", str(tmp_path / "fig4c"), *QUICK]) == 130
    assert shown == {"runtime": f"{main_program()} fig4c: warning: slow\n",
                     "long": f"{main_program()} fig4c: warning: slow\n",
                     "deprecation": "x.py:3: DeprecationWarning: old\n"}
    assert warnings.formatwarning is python_format


def test_sigterm_handler_of_the_calling_program_is_left_alone(tmp_path, monkeypatch, capsys):
    """A program that handles SIGTERM itself and calls the studies' main keeps its handler: it
    is neither replaced during the study nor reset after."""
    import signal

    def own_handler(signum, frame):
        raise AssertionError("not called: no signal is sent")
    seen = {}

    def record_handler(*args, **kwargs):
        seen["during"] = signal.getsignal(signal.SIGTERM)
        raise KeyboardInterrupt
    monkeypatch.setattr("studies.figures.run_fig4c", record_handler)
    previous = signal.signal(signal.SIGTERM, own_handler)
    try:
        assert studies_main(["fig4c", "--out", str(tmp_path / "fig4c"), *QUICK]) == 130
        assert seen["during"] is own_handler
        assert signal.getsignal(signal.SIGTERM) is own_handler
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert capsys.readouterr().err.endswith("interrupted; the files written before are whole\n")


def test_ctrl_c_while_a_study_loads_its_libraries_is_one_line(monkeypatch, capsys):
    """A study's import (pandas, pyarrow, SciPy: a second or more) sat outside the interrupt's
    handler: Ctrl-C there was a 40-line traceback (an audit, 2026-12)."""
    import studies.__main__ as entry

    def interrupted_import(name):
        raise KeyboardInterrupt
    monkeypatch.setattr(entry.importlib, "import_module", interrupted_import)
    assert studies_main(["fig4c", *QUICK]) == 130
    assert capsys.readouterr().err == (f"{main_program()} fig4c: interrupted; the files "
                                       f"written before are whole\n")


def test_ctrl_c_after_the_output_folder_was_removed_is_still_one_line(tmp_path, monkeypatch,
                                                                      capsys):
    """Ctrl-C removes the empty folders the run made, and one may be gone already (removed
    from another shell while the run went on): the interrupt is still one line and exit 130,
    not a FileNotFoundError from looking into the missing folder."""
    def removed_then_interrupted(out, *args, **kwargs):
        out.folder.rmdir()
        raise KeyboardInterrupt
    monkeypatch.setattr("studies.figures.run_fig4c", removed_then_interrupted)
    out = tmp_path / "fig4c"
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 130
    assert capsys.readouterr().err == (f"{main_program()} fig4c: interrupted; the files "
                                       f"written before are whole\n")
    assert not out.exists()


def test_a_refusal_after_the_output_folder_was_made_removes_it_if_empty(tmp_path, monkeypatch,
                                                                       capsys):
    """A check that can only run once the folder is made (a study's own) left it empty; a
    folder that was there before stays."""
    def refuse(*args, **kwargs):
        raise cli.StudyArgumentError("--flag: refused")
    monkeypatch.setattr("studies.figures.run_fig4c", refuse)
    out = tmp_path / "new"
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 2
    assert capsys.readouterr().err == f"{main_program()} fig4c: error: --flag: refused\n"
    assert not out.exists()
    there = tmp_path / "there"
    there.mkdir()
    assert studies_main(["fig4c", "--out", str(there), *QUICK]) == 2
    assert there.is_dir()


def test_a_full_disk_is_a_one_line_error_naming_the_folder(tmp_path, monkeypatch, capsys):
    """ENOSPC while a study writes its table: exit 2, one line naming --out's folder, no
    traceback; the file is not left half-written."""
    def write_table(out, *args, **kwargs):
        out.write_csv(pd.DataFrame({"gait": ["A1"]}), "fig4c.csv")

    def full_disk(source, target):
        raise OSError(28, os.strerror(28))
    monkeypatch.setattr("studies.figures.run_fig4c", write_table)
    monkeypatch.setattr(provenance.os, "replace", full_disk)
    out = tmp_path / "out"
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err.strip()
    assert f"--out {out}: cannot write fig4c.csv (No space left on device)" in error
    assert len(error.splitlines()) == 1 and not (out / "fig4c.csv").exists()


def test_output_names_stay_in_the_output_folder(no_compute, tmp_path, capsys):
    """--out "" (the working folder) is refused; a study's own file names may name a
    subfolder but never leave the folder."""
    assert studies_main(["fig4c", "--out", "", *QUICK]) == 2
    assert "--out: an empty folder name" in capsys.readouterr().err
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    assert out.path("animations/A1.gif") == tmp_path / "animations" / "A1.gif"
    for name in ("../escape.csv", "/tmp/escape.csv", "a/../../b.csv", ""):
        with pytest.raises(ValueError, match="would leave the output folder"):
            out.path(name)


def test_cycles_shorter_than_a_step_is_an_error_naming_cycles(no_compute, tmp_path, capsys):
    """--cycles 0.0001 of the 3.15-s period is 0.3 ms, under the 1-ms step."""
    assert studies_main(["fig4c", "--cycles", "0.0001", "--out", str(tmp_path / "out"),
                         "--no-progress"]) == 2
    error = capsys.readouterr().err.strip()
    assert "--cycles 0.0001 (0.000315 s) is less than one step (dt = 0.001 s)" in error \
        and len(error.splitlines()) == 1
    with pytest.raises(ValueError, match=r"cycles must give at least one step.*params\[0\]"):
        taichi_star.batch.run_batch([StarParams()], cycles=1e-4)


@pytest.mark.parametrize("flags, message", [
    (["--cycles", "1e9"], "--cycles 1e+09 (3.15e+09 s) at dt = 0.001 s is 3.15e+12 time steps per "
                          "instance; the limit is 2147483647"),
    (["--dt", "1e-12"], "--cycles 3 (9.45 s) at dt = 1e-12 s is 9.45e+12 time steps"),
    # adaptive: refused by the fewest steps, at dt_max (1e4 cycles at the accurate preset's
    # 0.05 s are 6.3e5 steps: accepted)
    (["--preset", "accurate", "--cycles", "1e9"], "--cycles 1e+09 (3.15e+09 s) at dt_max = 0.05 "
                                                  "s is 6.3e+10 time steps"),
    # --quick runs 0.2 s whatever --cycles says: its length is what is checked
    (["--quick", "--dt", "1e-12"], "--quick (0.2 s) at dt = 1e-12 s is 2e+11 time steps")])
def test_unbounded_runs_are_a_one_line_error_with_the_estimate(no_compute, tmp_path, capsys,
                                                               flags, message):
    assert studies_main(["fig4c", *flags, "--out", str(tmp_path / "out"), "--no-progress"]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1


@pytest.mark.parametrize("study, message", [
    ("work_precision", "--cycles 1e+09 (3.15e+09 s) at the grid's finest step 0.000125 s is "
                       "2.52e+13 time steps"),
    ("stability", "--cycles 1e+09 (3e+08 s) at dt (--dts-ms) 0.0005 s is 6e+11 time steps")])
def test_studies_with_their_own_step_grids_refuse_unbounded_cycles(no_compute, tmp_path, capsys,
                                                                  study, message):
    """The studies that pick their own steps check --cycles against the finest of them."""
    assert studies_main([study, "--cycles", "1e9", "--out", str(tmp_path / "out"),
                         "--no-progress"]) == 2
    error = capsys.readouterr().err.strip()
    assert message in error and len(error.splitlines()) == 1


def test_a_full_disk_while_drawing_a_plot_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    """A plot is saved by matplotlib, not by Output: ENOSPC there is still one line naming the
    file (exit 2), not a traceback."""
    plot = tmp_path / "out" / "fig4c.png"

    def full_disk(*args, **kwargs):
        raise OSError(28, os.strerror(28), str(plot))
    monkeypatch.setattr("studies.figures.run_fig4c", full_disk)
    assert studies_main(["fig4c", "--out", str(tmp_path / "out"), *QUICK]) == 2
    error = capsys.readouterr().err.strip()
    assert f"cannot write {plot} (No space left on device)" in error
    assert len(error.splitlines()) == 1


def test_the_machine_record_names_the_vector_sets_and_the_caches(tmp_path):
    x86 = ("processor : 0\nflags : fpu sse sse2 avx fma avx2\n\n"
           "processor : 1\nflags : fpu sse2 avx avx2 fma avx512f\n")
    # the first processor's flags, in the order of VECTOR_EXTENSIONS (the widest last)
    assert provenance.vector_extensions(x86) == ["sse2", "avx", "fma", "avx2"]
    assert provenance.cpu_model("model name : Some CPU\n" + x86) == "Some CPU"
    assert provenance.vector_extensions("Features : fp asimd evtstrm sve") == ["asimd",
                                                                                    "sve"]
    assert provenance.vector_extensions("model name : a CPU") == []
    for index, (level, kind, size) in enumerate([("1", "Data", "48K"),
                                                 ("1", "Instruction", "64K"),
                                                 ("2", "Unified", "2048K"),
                                                 ("3", "Unified", None)]):
        folder = tmp_path / f"index{index}"
        folder.mkdir()
        (folder / "level").write_text(level + "\n")
        (folder / "type").write_text(kind + "\n")
        if size:
            (folder / "size").write_text(size + "\n")
    # a cache whose size cannot be read is left out, not guessed
    assert provenance.cache_sizes(tmp_path) == {"L1d": "48K", "L1i": "64K", "L2": "2048K"}
    assert provenance.cache_sizes(tmp_path / "missing") == {}
    assert {"vector_extensions", "caches"} <= set(provenance.machine())


def study_parsers():
    """(name, parser) of every study built on `build_parser` (reproduce has its own small
    parser)."""
    import importlib

    for name in study_names():
        module = importlib.import_module(f"studies.{name}")
        if hasattr(module, "build_parser"):
            yield name, module.build_parser()


def test_every_study_flag_with_a_default_shows_it_in_its_help():
    """docs/studies.md: `--help` gives each flag's default (five flags did not say theirs: an
    audit); the parser adds it where the help text does not."""
    import argparse

    unsaid = []
    for name, parser in study_parsers():
        for action in parser._actions:
            shown = action.default not in (None, [], False) or (
                isinstance(parser, cli.StudyParser) and action.dest in parser.quick_defaults)
            if action.option_strings and shown and "default" not in (action.help or "") \
                    and not isinstance(action, argparse._HelpAction):
                unsaid.append(f"{name} {action.option_strings[0]}")
            # argparse's own flags keep their words (-h showed "(default ==SUPPRESS==)")
            assert "SUPPRESS" not in (action.help or ""), (name, action.option_strings)
    assert unsaid == []


def test_every_studys_preset_help_states_the_preset_it_runs():
    """strokes ran the identified preset while its help said "default paper" (its default was
    set after the help was written: an audit, 2026-12)."""
    checked = []
    for name, parser in study_parsers():
        for action in parser._actions:
            if "--preset" in action.option_strings:
                default = parser.parse_args([]).preset
                assert f"(default {default})" in action.help, (name, action.help)
                checked.append((name, default))
    assert ("strokes", "identified") in checked and ("fig4c", "paper") in checked


@pytest.mark.parametrize("quick_flags", [False, True])
def test_no_flag_says_its_default_twice(quick_flags):
    """Each flag's help says "default" once: the parser adds a default only where the help
    does not say it (a flag with a --quick default said it twice, "(default 512) (default
    512; --quick 2)": an audit), for the flags without a --quick default and with one."""
    twice = []
    for name, parser in study_parsers():
        for action in parser._actions:
            if (action.dest in getattr(parser, "quick_defaults", {})) != quick_flags:
                continue
            if (action.help or "").count("default") > 1:
                twice.append((name, action.option_strings, action.help))
    assert twice == []


@pytest.mark.parametrize("help_text, shown", [
    ("batch size", "batch size (default 512; --quick 2)"),
    ("batch size (default 512)", "batch size (default 512) (--quick 2)"),
])
def test_a_quick_flag_says_both_defaults_once(help_text, shown):
    parser = cli.StudyParser("sweep", "a study")
    action = parser.add_argument("--batch", type=int, default=512, quick=2, help=help_text)
    assert action.help == shown
    assert parser.parse_args(["--quick"]).batch == 2 and parser.parse_args([]).batch == 512
