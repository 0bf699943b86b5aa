"""The studies' shared code (studies/cli.py, provenance.py, __main__.py and figures.py): flag
refusals in one line, ranges and lists, the work estimate, run stores and output names, the
launcher's exits and errors, the recorded command, machine and commit, and the Fig. 4b table.
Found by a mutation audit (2026-12-07): each test kills a change of the code that the suite let
live."""

from types import SimpleNamespace

import pytest

from taichi_star import SolverConfig

from studies import cli
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]


def one_line_refusal(argv, tmp_path, capsys) -> str:
    """The launcher's one-line refusal (exit 2, no traceback, no output folder made)."""
    out = tmp_path / "out"
    assert studies_main([*argv, "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1 and "Traceback" not in error, error
    assert not out.exists()
    return error


# --------------------------------------------------------------------------- shared flags

def test_an_out_of_blanks_is_an_empty_folder_name(no_compute, tmp_path, capsys, monkeypatch):
    """--out "  " (blanks alone) is refused as an empty name, as --out "" is, not made as a
    folder named by two blanks in the current folder."""
    monkeypatch.chdir(tmp_path)
    assert studies_main(["fig4c", "--out", "  ", *QUICK]) == 2
    assert "--out: an empty folder name" in capsys.readouterr().err
    assert not (tmp_path / "  ").exists()


@pytest.mark.parametrize("value", ["-1:1:3", "-1", "-.5"])
def test_a_value_that_starts_with_a_minus_is_refused_for_its_range(no_compute, tmp_path, capsys,
                                                                    value):
    """"--alpha -1:1:3" was read as an unknown flag: argparse's "expected one argument" named
    neither the value nor the range (an audit, 2026-12); the value's own check now speaks."""
    assert studies_main(["sweep", "--quick", "--alpha", value, "--out",
                         str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "--alpha: alpha must be a real number in [0, 10], got -" \
        in error, error


@pytest.mark.parametrize("name", ["", "  "])
def test_a_redraw_of_an_empty_folder_name_is_refused(no_compute, tmp_path, capsys, monkeypatch,
                                                     name):
    """gait_design --redraw '' read the current folder: a gait_design.csv there would have
    been drawn again (an audit, 2026-12)."""
    monkeypatch.chdir(tmp_path)
    assert studies_main(["gait_design", "--redraw", name]) == 2
    assert "--redraw: an empty folder name" in capsys.readouterr().err


def test_a_prefix_with_a_backslash_is_refused_in_one_line(no_compute, tmp_path, capsys):
    """A backslash in --prefix is refused by the flag's check (it reached Output.path's
    ValueError, a traceback, after the output folder was made)."""
    error = one_line_refusal(["fig4c", "--prefix", "a\\b"], tmp_path, capsys)
    assert "--prefix: 'a\\\\b' is not a file name" in error


def test_a_missing_gpu_is_refused_naming_the_arch(no_compute, tmp_path, capsys, monkeypatch):
    """--arch gpu where Taichi has no GPU backend: one line naming the available archs."""
    monkeypatch.setattr("taichi_star.runtime.available_archs", lambda: ["cpu"])
    error = one_line_refusal(["fig4c", "--arch", "gpu"], tmp_path, capsys)
    assert "--arch gpu: no such backend on this machine; available archs: cpu" in error


def test_a_primitives_table_of_a_header_alone_is_refused_in_one_line(no_compute, tmp_path,
                                                                      capsys):
    """A primitives table with its columns and no rows: read_table's "no rows" (it reached
    the planner's model, a TypeError traceback)."""
    columns = ["gait", "status", "period_s", "dt_s", "step_x_mm", "step_y_mm", "turn_deg"]
    table = tmp_path / "primitives.csv"
    table.write_text(",".join(columns) + "\n")
    error = one_line_refusal(["plan", "--primitives", str(table)], tmp_path, capsys)
    assert f"--primitives {table}: not a primitives table" in error and "; no rows)" in error


# --------------------------------------------------------------------------- ranges

def test_a_log_range_takes_its_keyword_in_any_case():
    assert cli.parse_values("1:100:3:LOG", "--alpha") == pytest.approx([1.0, 10.0, 100.0])


def test_a_range_of_the_most_points_is_taken_and_one_more_refused():
    assert len(cli.parse_range(f"0:1:{cli.MAX_INSTANCES}", "--alpha")) == cli.MAX_INSTANCES
    with pytest.raises(cli.StudyArgumentError, match="at most 1000000"):
        cli.parse_range(f"0:1:{cli.MAX_INSTANCES + 1}", "--alpha")


def test_a_range_of_one_point_needs_equal_ends():
    assert cli.parse_range("0.5:0.5:1", "--alpha") == [0.5]
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^--alpha: range '0.5:0.6:1' has one point but start != stop$"):
        cli.parse_range("0.5:0.6:1", "--alpha")


@pytest.mark.parametrize("text", ["0:1e6:3:log", "1e6:0:3:log", "-1:1e6:3:log"])
def test_a_log_range_from_zero_or_below_is_a_study_argument_error(text):
    """numpy's geomspace raised its own ValueError (a traceback) for a zero end."""
    with pytest.raises(cli.StudyArgumentError, match="log range .* needs start, stop > 0"):
        cli.parse_range(text, "--youngs-modulus")


# --------------------------------------------------------------------------- estimates

def test_the_batch_estimate_shares_the_instances_among_the_periods():
    """10 instances over two periods (5 each): 5 × 200 + 5 × 600 robot-steps at 10 ms for
    --cycles 2 of 1 s and 3 s, not 10 × (200 + 600)."""
    args = SimpleNamespace(quick=False, cycles=2.0)
    config = SolverConfig(dt=0.01)
    assert cli.tell_batch_work(args, config, 10, periods=[1.0, 3.0]) == pytest.approx(4000)


def test_a_batch_past_what_its_arch_finishes_is_refused_before_it_is_built(monkeypatch):
    """A sweep of 13 years started with a warning: the study only warned of its batch, and
    each chunk passed the library's check alone; the CLI held every study to one H100's bound
    even on the CPU (an audit, 2026-12). On 2 CPU cores 1.296e12 robot-steps (2,000,000
    instances × 648,000 steps) start with the long-work warning and 100 steps more each are
    refused with the estimate; on a GPU (the fastest machine's bound) the same batch starts,
    and spread by a Dask --scheduler over machines a batch past any one machine's bound does
    (with the warning)."""
    from taichi_star import timegrid
    from taichi_star.timegrid import LongWorkWarning

    monkeypatch.setattr(timegrid, "usable_cores", lambda: 2)
    config = SolverConfig(dt=0.01)

    def batch(cycles, arch="cpu", scheduler=None):
        args = SimpleNamespace(quick=False, cycles=cycles, arch=arch, scheduler=scheduler)
        return cli.tell_batch_work(args, config, 2_000_000, periods=[1.0])

    with pytest.warns(LongWorkWarning, match=r"1\.3e\+12 robot-steps: about"):
        assert batch(6480) == 1_296_000_000_000
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^the batch of 2,000,000 instances \(--cycles 6481 of its period\) "
                             r"is 1\.3e\+12 robot-steps: about 30 days even at 5e\+05 "
                             r"robot-steps/s \(this machine's 2 CPU cores"):
        batch(6481)
    with pytest.warns(LongWorkWarning):
        assert batch(6481, arch="gpu") == 1_296_200_000_000
    with pytest.raises(cli.StudyArgumentError, match=r"about 30 days even at 3\.6e\+06"):
        batch(46_657, arch="gpu")   # 9.3314e12 robot-steps: past one H100's 9.3312e12
    with pytest.warns(LongWorkWarning, match=r"9\.33e\+12 robot-steps: about"):
        assert batch(46_657, scheduler="tcp://cluster:8786") == 9_331_400_000_000


def test_a_batch_of_other_meshes_is_weighed_by_their_mean_nodes(monkeypatch):
    """A product's robots' mean nodes: the base's mesh where n_arc and n_limb are not swept,
    the mean over their combinations where they are (193, 241, 433 and 481 nodes: 337), the
    other axes aside. A batch of 386-node robots (twice the paper robot's work a step) is
    held to half the robot-steps on 2 CPU cores: 6.48e11 start, 100 steps more each are
    refused naming the mesh; the paper robot's same batch starts."""
    from taichi_star import StarParams, timegrid
    from taichi_star.timegrid import LongWorkWarning

    base = StarParams()
    assert cli.mean_nodes(base, {}) == 193.0
    assert cli.mean_nodes(base.replace(n_arc=1000), {"alpha": [0.1, 0.2]}) == 8049.0
    assert cli.mean_nodes(base, {"n_arc": [18, 48]}) == (193 + 433) / 2
    assert cli.mean_nodes(base, {"n_arc": [18, 48], "n_limb": [6, 12],
                                 "alpha": [0.1, 0.2, 0.3]}) == (193 + 241 + 433 + 481) / 4
    monkeypatch.setattr(timegrid, "usable_cores", lambda: 2)
    args = SimpleNamespace(quick=False, cycles=3240, arch="cpu", scheduler=None)
    config = SolverConfig(dt=0.01)
    with pytest.warns(LongWorkWarning, match=r"6\.48e\+11 robot-steps of robots of 386 nodes"):
        assert cli.tell_batch_work(args, config, 2_000_000, periods=[1.0], nodes=386) \
            == 648_000_000_000
    args.cycles = 3241
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^the batch of 2,000,000 instances \(--cycles 3241 of its period\) "
                             r"is 6\.48e\+11 robot-steps of robots of 386 nodes \(a step 2 "
                             r"times the work of one of the paper robot's 193\): about 30 days"):
        cli.tell_batch_work(args, config, 2_000_000, periods=[1.0], nodes=386)
    with pytest.warns(LongWorkWarning, match=r"6\.48e\+11 robot-steps: about"):
        cli.tell_batch_work(args, config, 2_000_000, periods=[1.0])


def test_a_sweep_of_a_fine_mesh_is_refused_by_its_nodes(no_compute, tmp_path, capsys,
                                                         monkeypatch):
    """The sweep's own check weighs its robots' nodes (`--set n_arc=1000`: 8,049, 41.7 times
    the work of a step): 2,000 robots for 10,000 periods are refused on 2 cores in one line
    before any compute, as the paper robot's would not be (6.3e10 robot-steps of 1.296e12)."""
    from taichi_star import timegrid

    monkeypatch.setattr(timegrid, "usable_cores", lambda: 2)
    out = tmp_path / "out"
    code = studies_main(["sweep", "--gaits", "A1", "--alpha", "0:1:2000", "--cycles", "10000",
                         "--set", "n_arc=1000", "--dt", "0.001", "--out", str(out)])
    error = capsys.readouterr().err
    assert code == 2 and len(error.strip().splitlines()) == 1, error
    assert "of robots of 8,049 nodes (a step 41.7 times the work" in error and not out.exists()


@pytest.mark.parametrize("text, kind", [("1,,2", float), ("1,2,", int),
                                        ("contract,,always", str)])
def test_an_empty_item_of_a_list_is_named_as_such(text, kind):
    """An empty item is "malformed" for every kind of list: a list of names took the empty
    name, and a list of numbers was told "'' is not a number"."""
    with pytest.raises(cli.StudyArgumentError,
                       match=rf"^--x: malformed list '{text}' \(an empty item\)$"):
        cli.parse_values(text, "--x", kind)


def test_a_field_named_with_hyphens_is_the_field():
    """--set youngs-modulus=5e6 (a flag's spelling) names youngs_modulus."""
    assert cli.parse_assignment("youngs-modulus=5e6", "--set") == ("youngs_modulus", [5e6])
    assert cli.parse_assignment(" added-mass-coeff =0,1", "--param") == \
        ("added_mass_coeff", [0.0, 1.0])


def test_all_gaits_are_the_255_non_empty_masks():
    gaits = cli.resolve_gaits("all")
    assert len(gaits) == len(set(gaits)) == 255
    assert gaits[0] == "A1" and gaits[-1] == "A1+A2+A3+A4+A5+A6+A7+A8"


# --------------------------------------------------------------------------- runs, output

def test_only_a_resumed_run_takes_the_stored_chunk_size(monkeypatch, tmp_path):
    """A fresh run into a run store holding a finished run (which it replaces) cuts its own
    chunks; --resume alone reads the stored run's chunk size."""
    monkeypatch.setattr(cli, "stored_chunk_size", lambda *args, **kwargs: 3)
    out = SimpleNamespace(folder=tmp_path, run_store=None)
    fresh = SimpleNamespace(run_dir=None, resume=False, chunk_size=None)
    assert cli.run_store(fresh, out) == tmp_path / "chunks" == out.run_store
    assert fresh.chunk_size is None
    resumed = SimpleNamespace(run_dir=str(tmp_path / "store"), resume=True, chunk_size=None)
    assert cli.run_store(resumed, out) == tmp_path / "store"
    assert resumed.chunk_size == 3


def test_an_interrupt_names_a_records_folder_only_when_it_holds_records(monkeypatch, tmp_path):
    done = tmp_path / "done"
    (done / "sub").mkdir(parents=True)
    out = SimpleNamespace(remove_if_unused=lambda: None, run_store=None, resume_records=done)
    monkeypatch.setattr(cli, "OPENED", [out])
    assert cli.interrupted() == "the files written before are whole"
    (done / "sub" / "a.json").write_text("{}")
    assert cli.interrupted() == (f"the finished work in {done} is kept: the same command with "
                                 f"--resume continues the run")


@pytest.mark.parametrize("name", ["a\\b.csv", "../x.csv", "/abs.csv", ""])
def test_an_output_name_that_could_leave_the_folder_is_refused(tmp_path, name):
    with pytest.raises(ValueError, match="would leave the output folder"):
        cli.Output.path(SimpleNamespace(folder=tmp_path), name)
    assert list(tmp_path.iterdir()) == []


def test_a_missing_parameter_or_step_is_an_empty_cell(tmp_path):
    """NaN in an exact column (a parameter, dt_s) is written as an empty cell, which the
    studies' readers (`NAMES_AS_WRITTEN`) read as missing, not as the text "nan"."""
    import numpy as np
    import pandas as pd
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    frame = pd.DataFrame({"alpha": [0.5, np.nan], "dt_s": [np.nan, 0.001],
                          "speed_mm_s": [1.0, 2.0]})
    assert out.write_csv(frame, "t.csv").read_text().splitlines() == \
        ["alpha,dt_s,speed_mm_s", "0.5,,1", ",0.001,2"]
    back = pd.read_csv(tmp_path / "t.csv", **cli.NAMES_AS_WRITTEN)
    assert back["alpha"].isna().tolist() == [False, True]
    assert back["dt_s"].isna().tolist() == [True, False]


def test_a_tables_details_add_to_the_runs(tmp_path):
    import json
    import pandas as pd
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [],
                     extra={"grid": "coarse"})
    out.write_csv(pd.DataFrame({"x": [1]}), "t.csv", extra={"rows": "one"})
    out.write_csv(pd.DataFrame({"x": [1]}), "u.csv")
    assert json.loads((tmp_path / "t.csv.json").read_text())["details"] == \
        {"grid": "coarse", "rows": "one"}
    assert json.loads((tmp_path / "u.csv.json").read_text())["details"] == {"grid": "coarse"}


def test_a_file_written_twice_is_reported_once(tmp_path, capsys):
    """Once across calls, and once within one call (`wrote(c, c)` listed c twice: the check ran
    against the list as it was before the call; an audit, 2026-12-07)."""
    out = cli.Output(SimpleNamespace(study="fig4c", out=str(tmp_path), quick=False), [])
    out.wrote(tmp_path / "a.png")
    out.wrote(str(tmp_path / "a.png"), tmp_path / "b.png")
    out.wrote(tmp_path / "c.png", tmp_path / "c.png")
    out.report()
    assert capsys.readouterr().out.splitlines() == [
        f"  wrote {tmp_path / name}" for name in ("a.png", "b.png", "c.png")]


def test_the_run_place_flags_are_left_out_in_either_spelling():
    assert cli.flags_of_run(["--out=results", "--workers", "2", "--no-progress", "--out", "x",
                             "--replace-committed", "--quick"]) == ["--workers", "2", "--quick"]


# --------------------------------------------------------------------------- the launcher

def test_h_alone_lists_the_studies(capsys):
    assert studies_main(["-h"]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith("usage: ") and "\nstudies:\n" in captured.out
    assert captured.err == ""


@pytest.mark.parametrize("number", [28, 122])  # ENOSPC, EDQUOT (a quota full: no room either)
def test_a_write_that_found_no_room_is_one_line(tmp_path, monkeypatch, capsys, number):
    import errno
    import os
    assert number in (errno.ENOSPC, errno.EDQUOT)
    plot = tmp_path / "out" / "fig4c.png"

    def no_room(*args, **kwargs):
        raise OSError(number, os.strerror(number), str(plot))
    monkeypatch.setattr("studies.figures.run_fig4c", no_room)
    assert studies_main(["fig4c", "--out", str(tmp_path / "out"), *QUICK]) == 2
    error = capsys.readouterr().err.strip()
    assert f"cannot write {plot} ({os.strerror(number)})" in error and len(error.splitlines()) == 1


def test_another_os_error_keeps_its_traceback(tmp_path, monkeypatch):
    """A fault (a permission refused where the checks let it by) is shown as it is, not as a
    full disk."""
    def refused(*args, **kwargs):
        raise PermissionError(13, "Permission denied", "somewhere")
    monkeypatch.setattr("studies.figures.run_fig4c", refused)
    with pytest.raises(PermissionError):
        studies_main(["fig4c", "--out", str(tmp_path / "out"), *QUICK])


@pytest.mark.parametrize("code, status", [("stopped", 2), (None, 0), (3, 3), (0, 0)])
def test_a_studys_exit_gives_its_status(tmp_path, monkeypatch, code, status):
    """sys.exit with a message is a failure (2); sys.exit() or sys.exit(None) a success, as
    Python's own exit (it was 2: an audit, 2026-12-07); a number is that status."""
    def leaves(*args, **kwargs):
        raise SystemExit(code)
    monkeypatch.setattr("studies.figures.run_fig4c", leaves)
    assert studies_main(["fig4c", "--out", str(tmp_path / "out"), *QUICK]) == status


# --------------------------------------------------------------------------- provenance

def test_a_cpu_runs_timing_columns_name_no_gpu(monkeypatch):
    from studies import provenance
    monkeypatch.setattr(provenance, "machine",
                        lambda: {"cpu_model": "Some CPU", "cores": 16, "gpus": ["H100"]})
    monkeypatch.setattr(provenance, "nvidia_smi", lambda field: ["550.1"])
    assert provenance.machine_columns("cpu") == {
        "machine": "Some CPU (16 cores)", "cpu_model": "Some CPU", "cores": 16, "gpu": "",
        "gpu_driver": ""}
    assert provenance.machine_columns("gpu") == {
        "machine": "Some CPU (16 cores) + H100", "cpu_model": "Some CPU", "cores": 16,
        "gpu": "H100", "gpu_driver": "550.1"}


@pytest.mark.parametrize("code, shown", [
    ({"commit": "0123456789abcdef", "dirty": True}, "0123456-dirty"),
    ({"commit": "0123456789abcdef", "dirty": False}, "0123456"),
    ({"commit": None, "dirty": None}, "unknown")])
def test_the_short_commit_says_a_dirty_checkout(monkeypatch, code, shown):
    from studies import provenance
    monkeypatch.setattr(provenance, "code_version", lambda: code)
    assert provenance.short_commit() == shown


def test_resume_takes_a_run_dir_without_out(tmp_path):
    """--resume needs the run's folder: --out, or --run-dir alone (the run store to continue)."""
    parser = cli.StudyParser("sweep", "a study")
    cli.add_execution_flags(parser)
    cli.add_resume_flags(parser)
    args = cli.parse(parser, ["--resume", "--run-dir", str(tmp_path / "store")])
    assert args.resume and args.run_dir == str(tmp_path / "store") and args.out is None
    with pytest.raises(cli.StudyArgumentError,
                       match=r"^--resume: give --out \(the folder of the run to continue\) or "
                             r"--run-dir$"):
        cli.parse(parser, ["--resume"])


def test_a_command_of_no_flags_ends_with_the_study(monkeypatch):
    from studies import program, provenance
    monkeypatch.setattr(provenance, "LATEST_STUDY", {})
    assert provenance.record("fig4c", [])["command"] == f"{program()} fig4c"
    assert provenance.record("fig4c", ["--quick"])["command"] == f"{program()} fig4c --quick"


@pytest.mark.parametrize("dirty, said", [(True, "true"), (False, "false"), (None, "unknown")])
def test_a_figure_says_whether_the_checkout_was_dirty(monkeypatch, dirty, said):
    from studies import provenance
    monkeypatch.setattr(provenance, "code_version",
                        lambda: {"version": "1.0", "commit": "abc", "dirty": dirty})
    assert provenance.figure_metadata()["git_dirty"] == said


def test_a_source_hash_that_could_not_be_made_is_unknown(monkeypatch):
    from studies import provenance
    monkeypatch.setattr(provenance, "code_version", lambda: {
        "version": "1.0", "commit": None, "dirty": None, "source_sha256": None})
    assert provenance.figure_metadata()["source_sha256"] == "unknown"


# --------------------------------------------------------------------------- figures

def test_fig4b_cuts_the_experiment_at_the_simulated_span():
    """The experiment's curve ends where the simulation's does (1 s here), and a gait with no
    experiment has the simulation's curve alone."""
    import pandas as pd
    from studies import figures
    summary = pd.DataFrame({"instance": [0, 1], "gait": ["A1+A3+A5", "A2"]})
    trajectory = pd.DataFrame({"instance": [0, 0, 1, 1], "t_s": [0.0, 1.0, 0.0, 1.0],
                               "x_mm": [0.0, 3.0, 0.0, 1.0], "y_mm": [0.0, 4.0, 0.0, 0.0]})
    table = figures.fig4b_table(summary, trajectory, 1.0)
    experiment = table[table["source"] == "experiment"]
    assert len(experiment) > 2 and set(experiment["gait"]) == {"A1+A3+A5"}
    assert experiment["t_s"].max() <= 1.0 + 1e-9
    assert table[table["source"] == "simulation"]["displacement_mm"].tolist() == [0, 5, 0, 1]


def _drawn_fig4c(monkeypatch, tmp_path, caption):
    """The texts of the Fig. 4c figure `plot_fig4c` draws from a three-gait table: a gait
    swimming the paper's way, one swimming the other way, one whose run diverged. The figure
    is kept from `cli.write_figure`, which still writes the PNG."""
    import pandas as pd
    from studies import figures
    table = pd.DataFrame({
        "gait": ["A1", "A1+A2", "A1+A3"], "sim_speed_mm_s": [0.5, 2.0, float("nan")],
        "exp_speed_mm_s": [0.6, 1.5, 3.0], "exp_cycle_speed_std_mm_s": [0.1, 0.2, 0.3],
        "status": ["ok", "ok", "diverged"], "sim_direction": ["forward", "reverse", None],
        "paper_direction": ["forward", "forward", "reverse"],
        "direction_matches": [True, False, None]})
    table.to_csv(tmp_path / "fig4c.csv", index=False)
    drawn = []
    write = cli.write_figure
    monkeypatch.setattr(cli, "write_figure", lambda fig, path, **kw: (drawn.append(fig),
                                                                       write(fig, path, **kw))[1])
    figures.plot_fig4c(tmp_path / "fig4c.csv", tmp_path / "fig4c.png", caption=caption)
    assert (tmp_path / "fig4c.png").stat().st_size > 0
    (fig,) = drawn
    return fig


def test_fig4c_labels_each_bar_with_its_direction_red_where_it_disagrees(monkeypatch, tmp_path):
    """Over the simulated bars: "fwd" in black where the paper's direction is swum, "rev" in
    red where it is not, a failed run's status in red at the bar's foot; over the measured
    bars the paper's direction in black, above the error bar."""
    from matplotlib.colors import to_rgba
    fig = _drawn_fig4c(monkeypatch, tmp_path, caption="")
    labels = {(round(t.get_position()[0], 2), t.get_text()): (t.get_color(), t.get_position()[1])
              for t in fig.axes[0].texts}
    black, red = to_rgba("black"), to_rgba("red")
    assert {key: to_rgba(colour) for key, (colour, _) in labels.items()} == {
        (-0.19, "fwd"): black, (0.81, "rev"): red, (1.81, "diverged"): red,
        (0.19, "fwd"): black, (1.19, "fwd"): black, (2.19, "rev"): black}
    assert labels[(0.81, "rev")][1] == 2.0 and labels[(1.81, "diverged")][1] == 0.0
    assert labels[(2.19, "rev")][1] == pytest.approx(3.3)  # the measured bar and its std
    assert fig.texts == []  # no caption asked for, none drawn


def test_fig4c_writes_its_caption_small_and_gray_under_the_plot(monkeypatch, tmp_path):
    """The caption (the model and solver, or a note given) is the figure's one text of its
    own: at its bottom left, 7-point, gray, wrapped at 130 characters."""
    from matplotlib.colors import to_rgba
    note = "calibrated (alpha=0.8); paper preset, n_arc 24, euler h = 1 ms " + "x" * 100
    fig = _drawn_fig4c(monkeypatch, tmp_path, caption=note)
    (caption,) = fig.texts
    assert caption.get_text().replace("\n", " ") == note
    assert max(len(line) for line in caption.get_text().splitlines()) <= 130
    assert caption.get_position() == (0.01, 0.01) and caption.get_fontsize() == 7
    assert to_rgba(caption.get_color()) == to_rgba("0.35")


def test_the_fig4_titles_name_the_simulated_span():
    from studies import figures
    assert all("(the first 0.5 s from rest)" in title or "the first 0.5 s from rest" in title
               for title in figures.fig4_titles(0.5))
    assert all("the first" not in title for title in figures.fig4_titles())
