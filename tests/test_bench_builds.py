"""tools/bench_builds.py's summary: the best of each build's rounds per measured case, the
ratio after/before, and whether the builds' final states agree (synthetic runs)."""

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bench_builds(tool):
    return tool("bench_builds")


def _row(build, round_number, batch, rate, digest, section="batch", lanes=1):
    return {"build": build, "round": round_number, "section": section, "scenario": "all_terms",
            "preset": "paper", "batch_size": batch, "precision": "f64", "jacobian": "newton",
            "lanes": lanes, "robot_steps_per_s": rate, "final_state": digest}


def test_the_summary_takes_each_builds_best_round_and_compares_the_bits(bench_builds):
    table = pd.DataFrame([
        _row("before", 1, 5, 100.0, "aa"), _row("after", 1, 5, 190.0, "aa"),
        _row("before", 2, 5, 120.0, "aa"), _row("after", 2, 5, 180.0, "aa"),
        _row("before", 1, 64, 400.0, "bb"), _row("after", 1, 64, 390.0, "cc"),
        _row("before", 1, 64, 50.0, np.nan, "sensitivities"),
        _row("after", 1, 64, 80.0, np.nan, "sensitivities")])
    summary = bench_builds.summarise(table).set_index(["section", "batch_size"])
    five = summary.loc[("batch", 5)]
    # best rounds: before 120 (round 2), after 190 (round 1)
    assert five["before_robot_steps_per_s"] == 120.0
    assert five["after_robot_steps_per_s"] == 190.0
    assert five["ratio_after_to_before"] == pytest.approx(190.0 / 120.0)
    assert five["same_bits"] == "True"
    assert summary.loc[("batch", 64), "same_bits"] == "False"
    # a section that records no digest says nothing about the bits
    assert summary.loc[("sensitivities", 64), "same_bits"] == ""
    assert summary.loc[("sensitivities", 64), "ratio_after_to_before"] == pytest.approx(1.6)


def test_digests_and_hashes_of_digits_alone_stay_text_and_the_same_bits_agree(bench_builds,
                                                                             tmp_path):
    """A digest or short hash of digits alone was read as a number in the build whose table
    held no other, and as text in the other's: the same bits came out as differing (an
    audit). The rounds' tables are read with their text columns as text."""
    before, after = tmp_path / "before.csv", tmp_path / "after.csv"
    pd.DataFrame([_row("before", 1, 5, 100.0, "012345678901")]).assign(
        commit="0813637").drop(columns=["build", "round"]).to_csv(before, index=False)
    pd.DataFrame([_row("after", 1, 5, 110.0, "012345678901"),
                  _row("after", 1, 64, 120.0, "abcdef012345")]).assign(
        commit="1234e56").drop(columns=["build", "round"]).to_csv(after, index=False)
    table = pd.concat([bench_builds.read_round(before, "before", 1),
                       bench_builds.read_round(after, "after", 1)], ignore_index=True)
    assert table["commit"].tolist() == ["0813637", "1234e56", "1234e56"]
    assert bench_builds.summarise(table).set_index("batch_size").loc[5, "same_bits"] == "True"


def test_the_summary_keeps_the_lanes_apart(bench_builds):
    """A bench run with `--lanes 1,8` measures each case twice per build: each lanes setting is
    compared with its own; a table without the column (before the setting) ran one at a time."""
    table = pd.DataFrame([
        _row("before", 1, 512, 100.0, "aa"), _row("after", 1, 512, 110.0, "aa"),
        _row("before", 1, 512, 150.0, "aa", lanes=8), _row("after", 1, 512, 165.0, "aa", lanes=8)])
    summary = bench_builds.summarise(table).set_index("lanes")
    assert summary.loc[1, "ratio_after_to_before"] == pytest.approx(1.1)
    assert summary.loc[8, "before_robot_steps_per_s"] == 150.0
    assert summary.loc[8, "ratio_after_to_before"] == pytest.approx(1.1)
    unlabelled = bench_builds.summarise(table[table["lanes"] == 1].drop(columns="lanes"))
    assert unlabelled["lanes"].tolist() == [1]
    assert unlabelled["ratio_after_to_before"].tolist() == pytest.approx([1.1])


def test_a_build_from_before_a_column_is_compared_where_it_says_nothing(bench_builds):
    """A baseline from before the lanes setting and before the plain section's digest: its rows
    (lanes and digest missing) meet the other build's one-lane rows, and the bits of a case
    are compared only where both builds recorded them."""
    table = pd.DataFrame([
        _row("before", 1, 512, 80.0, np.nan, "plain", lanes=np.nan),
        _row("after", 1, 512, 90.0, "dd", "plain"),
        _row("before", 1, 64, 40.0, "ee", lanes=np.nan), _row("after", 1, 64, 50.0, "ee"),
        _row("after", 1, 64, 30.0, "ff", "sensitivities")])
    summary = bench_builds.summarise(table).set_index("section")
    assert len(summary) == 3 and summary["lanes"].tolist() == [1, 1, 1]
    # a section only the later build has: no ratio, and nothing to compare the bits with
    assert np.isnan(summary.loc["sensitivities", "ratio_after_to_before"])
    assert summary.loc["sensitivities", "same_bits"] == ""
    assert summary.loc["plain", "ratio_after_to_before"] == pytest.approx(90.0 / 80.0)
    assert summary.loc["plain", "same_bits"] == ""
    assert summary.loc["batch", "same_bits"] == "True"


def test_after_args_go_to_the_after_build_alone(bench_builds, tmp_path):
    common, extra = ["--batch-sizes", "64"], ["--plain-jacobians", "newton,lagged"]
    before = bench_builds.bench_command("before", common, extra, tmp_path)
    after = bench_builds.bench_command("after", common, extra, tmp_path)
    assert before[1:] == ["-m", "studies", "bench", *common, "--no-progress", "--out",
                          str(tmp_path)]
    assert after[1:] == ["-m", "studies", "bench", *common, *extra, "--no-progress", "--out",
                         str(tmp_path)]


def test_a_case_only_the_after_build_ran_has_its_figures_and_no_ratio(bench_builds):
    table = pd.DataFrame([_row("before", 1, 512, 80.0, "a", section="plain"),
                          _row("after", 1, 512, 90.0, "a", section="plain"),
                          {**_row("after", 1, 512, 200.0, "b", section="plain"),
                           "jacobian": "lagged"}])
    summary = bench_builds.summarise(table).set_index("jacobian")
    assert summary.loc["newton", "ratio_after_to_before"] == pytest.approx(90.0 / 80.0)
    assert summary.loc["lagged", "after_robot_steps_per_s"] == 200.0
    assert np.isnan(summary.loc["lagged", "before_robot_steps_per_s"])
    assert np.isnan(summary.loc["lagged", "ratio_after_to_before"])
    assert summary.loc["lagged", "same_bits"] == ""


def test_the_summary_keeps_each_setting_apart(bench_builds):
    """One and two worker processes (or the IR optimisation on and off, the GPU layouts and
    block sizes) are separate cases, each compared with its own (they were merged into one row
    whose best came from either: an audit, 2026-12)."""
    table = pd.DataFrame([
        {**_row("before", 1, 64, 100.0, "aa"), "workers": 1},
        {**_row("after", 1, 64, 110.0, "aa"), "workers": 1},
        {**_row("before", 1, 64, 190.0, "aa"), "workers": 2},
        {**_row("after", 1, 64, 209.0, "aa"), "workers": 2}])
    summary = bench_builds.summarise(table).set_index("workers")
    assert len(summary) == 2
    assert summary.loc[1, "before_robot_steps_per_s"] == 100.0
    assert summary.loc[2, "after_robot_steps_per_s"] == 209.0
    assert summary["ratio_after_to_before"].tolist() == pytest.approx([1.1, 1.1])


@pytest.mark.parametrize("argv, message", [
    (["--before", "no-such-revision", "--out", "{out}"],
     "--before no-such-revision: no such commit in "),
    (["--before", "HEAD", "--out", "{out}"], "are the same commit"),
    (["--before", "HEAD~1", "--rounds", "0", "--out", "{out}"], "--rounds must be >= 1, got 0"),
    (["--before", "HEAD~1", "--out", "{results}", "--", "--quick"],
     "runs with --quick never write into the committed results/"),
])
def test_bad_arguments_are_refused_before_anything_is_made(bench_builds, tmp_path, capsys, argv,
                                                           message):
    """A revision git does not know was a traceback after --out was made; the same commit twice
    left stale worktrees; --quick into results/ replaced the committed bench.csv (audits,
    2026-12): each is one refusal, exit 2, and no folder made."""
    out = tmp_path / "out"
    argv = [part.format(out=out, results=REPO / "results" / "scratch_bench") for part in argv]
    with pytest.raises(SystemExit) as stopped:
        bench_builds.main(argv)
    assert stopped.value.code == 2
    assert message in capsys.readouterr().err
    assert not out.exists() and not (REPO / "results" / "scratch_bench").exists()


def test_the_summarys_sidecar_records_the_command_the_summarising_code_and_the_tables_stamp(
        bench_builds, tmp_path):
    """The command as a shell reads it back (an argument with a space stays one), the after
    build's commit, the checkout that summarised (its commit and whether it was dirty) and
    the SHA-256 of the very bytes written: a summary regenerated by a later rule read as the
    one first written (an audit, 2026-12)."""
    import hashlib
    import json
    import shlex

    from taichi_star.provenance import code_version

    summary = bench_builds.summarise(pd.DataFrame([_row("before", 1, 5, 100.0, "aa"),
                                                   _row("after", 1, 5, 190.0, "aa")]))
    argv = ["--before", "e67d242", "--after", "HEAD", "--after-args",
            "--plain-jacobians newton,lagged", "--out", str(tmp_path), "--", "--steps", "5"]
    bench_builds.write_summary(tmp_path, summary, argv, 2, {"before": "e67d242",
                                                            "after": "abc1234"})
    sidecar = json.loads((tmp_path / "summary.csv.json").read_text())
    assert shlex.split(sidecar["command"])[2:] == argv
    assert sidecar["git_commit"] == "abc1234"
    assert sidecar["summarised_by"]["git_commit"] == code_version()["commit"]
    assert sidecar["summarised_by"]["git_dirty"] in (True, False)
    data = (tmp_path / "summary.csv").read_bytes()
    assert sidecar["table_sha256"] == hashlib.sha256(data).hexdigest()
    assert sidecar["table_rows"] == len(summary) == len(pd.read_csv(tmp_path / "summary.csv"))
