"""The bench study at two commits of this repository, interleaved: the before/after table that a
change's speed claims rest on. Each build is a git worktree at its commit (the package imported
from there); the rounds alternate before, after, before, after, ... on the same machine, so a
drift of the machine's speed falls on both. Writes into --out:

- `bench.csv`: every row of every run, with `build` (before/after) and `round`, and a sidecar
  listing each run's own provenance (command, commit, machine, date);
- `summary.csv`: per measured case (section, scenario, preset, batch size, precision,
  Jacobian) the best robot-steps/s of each build over the rounds, their ratio after/before,
  and whether the builds' final states agree bit for bit (`same_bits`, the digest the batch
  section records; empty where a section records none); its sidecar records the command, the
  after build's commit, the checkout that summarised (its commit, whether it was dirty, the
  date: `summarised_by`) and the table's rows and SHA-256 (`table_sha256`: a later edit shows).

    python tools/bench_builds.py --before 89677b5 --after HEAD --rounds 2 --out DIR -- \\
        --batch-sizes 5,40,64 --presets paper --sensitivity-counts 0,1 ...

Everything after `--` goes to `python -m studies bench` unchanged (`--out` and
`--no-progress` are added). `--after-args "..."` adds bench flags to the after build's runs
alone, for a setting the baseline does not have (`--plain-jacobians newton,lagged`): its cases
are measured in the same interleaved rounds, and the summary lists them with the after build's
figures alone (no ratio), beside the cases both builds ran.
"""

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd

REPO = Path(__file__).resolve().parents[1]
CASE = ["section", "scenario", "preset", "batch_size", "precision", "jacobian", "lanes"]
"""The columns that name one measured case of the bench study (tables without `lanes` ran one
instance at a time: 1)."""
SETTINGS = ["workers", "kernel_optimisation", "layout", "block_dim"]
"""More columns that tell cases apart where a table has them (one and two worker processes,
the IR optimisation on and off, the GPU layouts and block sizes were merged into one row, and
their best compared across settings: an audit, 2026-12)."""
TEXT_COLUMNS = {"commit": str, "final_state": str}
"""Columns of a bench table read as text: a short hash or a state's digest can be digits alone
(one in 27 hashes, one in 280 digests), which pandas read as numbers, so that a digest read as
a number in one build's table and as text in the other's made the same bits differ (an
audit)."""
COMMITTED_RESULTS = REPO / "results"
"""The committed results: a run with the bench's --quick never writes there (the studies'
rule, `studies.cli.check_folder_name`)."""


def worktree(revision: str, parent: Path) -> Path:
    """A detached git worktree of `revision` under parent."""
    path = parent / revision.replace("/", "_")
    subprocess.run(["git", "worktree", "add", "--detach", str(path), revision], cwd=REPO,
                   check=True, capture_output=True)
    return path


def commit_of(revision: str) -> str:
    """The short hash of `revision`, or "" where git knows no such commit."""
    found = subprocess.run(["git", "rev-parse", "--verify", "--quiet", "--short",
                            f"{revision}^{{commit}}"], cwd=REPO, capture_output=True, text=True)
    return found.stdout.strip() if found.returncode == 0 else ""


def check_arguments(parser, args, bench_args) -> dict:
    """{"before": commit, "after": commit}, or the parser's one-line refusal (exit 2) before
    anything is made: a revision git does not know (a traceback after --out was made), the
    same commit twice (its second worktree failed and left stale entries), --rounds below 1,
    or the bench's --quick into the committed results/ (it replaced results/bench.csv: audits,
    2026-12)."""
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    builds = {build: commit_of(getattr(args, build)) for build in ("before", "after")}
    for build, commit in builds.items():
        if not commit:
            parser.error(f"--{build} {getattr(args, build)}: no such commit in {REPO}")
    if builds["before"] == builds["after"]:
        parser.error(f"--before {args.before} and --after {args.after} are the same commit "
                     f"({builds['after']}): nothing to compare")
    out = Path(args.out).resolve()
    if "--quick" in bench_args and (out == COMMITTED_RESULTS or COMMITTED_RESULTS in out.parents):
        parser.error(f"--out {args.out}: runs with --quick never write into the committed "
                     f"results/ (give another folder)")
    return builds


def bits_agree(rows: pd.DataFrame) -> str:
    """"True" or "False": whether every run of one case ended in the same state, or "" where
    one build did not run it or recorded no digest for it (a section without one, or a build
    from before it)."""
    recorded = rows.dropna(subset=["final_state"])
    if set(recorded["build"]) != {"before", "after"}:
        return ""
    return str(recorded["final_state"].nunique() == 1)


def summarise(table: pd.DataFrame) -> pd.DataFrame:
    """One row per CASE: best robot-steps/s per build, ratio after/before, same_bits."""
    # a row without lanes (a build from before the setting, a section that does not record
    # it) ran one instance at a time
    table = table.assign(lanes=table["lanes"].fillna(1) if "lanes" in table else 1)
    case = CASE + [c for c in SETTINGS if c in table.columns]
    keyed = table.assign(**{c: table[c].fillna("") for c in case})
    best = keyed.pivot_table(index=case, columns="build", values="robot_steps_per_s",
                             aggfunc="max")
    summary = best.rename(columns=lambda b: f"{b}_robot_steps_per_s").reset_index()
    summary["ratio_after_to_before"] = (summary["after_robot_steps_per_s"]
                                        / summary["before_robot_steps_per_s"])
    digests = keyed.groupby(case)[["build", "final_state"]].apply(bits_agree)
    return summary.merge(digests.rename("same_bits").reset_index(), on=case)


def bench_command(build: str, bench_args, after_args, run_out: Path):
    """The bench study's command line for one run of `build` ("before" or "after"):
    `bench_args` for both, `after_args` for the after build alone."""
    extra = list(after_args) if build == "after" else []
    return [sys.executable, "-m", "studies", "bench", *bench_args, *extra, "--no-progress",
            "--out", str(run_out)]


def read_round(path, build: str, round_number: int) -> pd.DataFrame:
    """One bench run's table, its text columns as text (`TEXT_COLUMNS`), with its build and
    round."""
    return pd.read_csv(path, dtype=TEXT_COLUMNS).assign(build=build, round=round_number)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    split = argv.index("--") if "--" in argv else len(argv)
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, help="baseline commit")
    parser.add_argument("--after", default="HEAD", help="commit measured against it")
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds (>= 1)")
    parser.add_argument("--out", required=True, help="folder for the tables")
    parser.add_argument("--after-args", default="",
                        help="bench flags for the after build's runs alone (one quoted string)")
    args = parser.parse_args(argv[:split])
    bench_args = argv[split + 1:]
    builds = check_arguments(parser, args, bench_args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    frames, runs = [], []
    with tempfile.TemporaryDirectory() as scratch:
        trees = {build: worktree(commit, Path(scratch)) for build, commit in builds.items()}
        try:
            for round_number in range(1, args.rounds + 1):
                for build, tree in trees.items():
                    run_out = Path(scratch) / f"{build}_{round_number}"
                    command = bench_command(build, bench_args, shlex.split(args.after_args),
                                            run_out)
                    print(f"round {round_number}, {build} ({builds[build]})", flush=True)
                    subprocess.run(command, cwd=tree, check=True, env={
                        **os.environ, "PYTHONPATH": str(tree)})
                    frames.append(read_round(run_out / "bench.csv", build, round_number))
                    runs.append(json.loads((run_out / "bench.csv.json").read_text()))
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO,
                               capture_output=True)
    table = pd.concat(frames, ignore_index=True)
    table = table[["build", "round"] + [c for c in table.columns if c not in ("build", "round")]]
    table.to_csv(out / "bench.csv", index=False)
    (out / "bench.csv.json").write_text(json.dumps({"runs": runs}, indent=1, default=str))
    summary = summarise(table)
    write_summary(out, summary, argv, args.rounds, builds)
    print(summary.to_string(index=False))


def write_summary(out: Path, summary: pd.DataFrame, argv, rounds: int, builds: dict):
    """summary.csv in `out` and its sidecar: the command (`argv` quoted as a shell reads it),
    the after build's commit (what was measured), the code record of this checkout, which
    summarised (`summarised_by`: a table rewritten by a later version of this tool says so),
    and the table's stamp. A summary's sidecar recorded the command and the commit alone, so
    that a table regenerated by a later rule read as the one first written (an audit,
    2026-12)."""
    from taichi_star.provenance import code_record, table_stamp

    data = summary.to_csv(index=False).encode()
    (out / "summary.csv").write_bytes(data)
    (out / "summary.csv.json").write_text(json.dumps({
        "study": "bench", "command": "python tools/bench_builds.py " + shlex.join(argv),
        "description": f"the best of {rounds} interleaved rounds per case and build "
                       f"(before: {builds['before']}, after: {builds['after']})",
        "git_commit": builds["after"], "summarised_by": code_record(),
        **table_stamp(len(summary), data)}, indent=1, default=str))


if __name__ == "__main__":
    main()
