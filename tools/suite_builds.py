"""The test suite's wall time at two commits of this repository, interleaved, each run with an
empty Taichi offline cache as on a fresh CI machine: the before/after figures that a claim
about the suite's time rests on. Each build is a git worktree at its commit beside a link to
this checkout's `../shared` (as CI places it); the rounds alternate the builds, the second
round in the opposite order, so that a drift of the machine's speed falls on both. Writes
`suite.csv` into --out (one row per run: build, commit, round, wall and pytest's own seconds,
the counts of its last line, the node ids of the tests that failed, the name of its log:
pytest's output, beside the table) with a provenance sidecar.

    python tools/suite_builds.py --before b62d281 --after HEAD --rounds 3 --out DIR
"""

import argparse
import datetime
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from bench_builds import REPO, commit_of, worktree

sys.path.insert(0, str(REPO))  # the studies package, for the machine's description
from studies.provenance import machine_columns  # noqa: E402

COUNTS = ("passed", "failed", "skipped", "errors")
"""The counts of pytest's last line that `suite.csv` keeps (absent ones are 0)."""


def last_line_figures(output: str) -> dict:
    """{"pytest_s": seconds, "passed": n, ...} from the last summary line of `pytest -q`
    ("1241 passed, 5 skipped, 4 warnings in 236.09s (0:03:56)"); ValueError if there is none."""
    lines = [line for line in output.splitlines() if re.search(r" in [\d.]+s", line)
             and any(word in line for word in ("passed", "failed", "error"))]
    if not lines:
        raise ValueError("no pytest summary line in the output")
    line = lines[-1]
    figures = {"pytest_s": float(re.search(r" in ([\d.]+)s", line).group(1))}
    for count in COUNTS:
        match = re.search(rf"(\d+) {count[:-1] if count == 'errors' else count}", line)
        figures[count] = int(match.group(1)) if match else 0
    return figures


def failed_tests(output: str) -> str:
    """The node ids of the tests that failed or errored, from the short summary of `pytest -q`
    ("FAILED tests/x.py::test_y - AssertionError: ..."), joined by spaces in the summary's
    order ("" for none): a run with a failure says which, not only how many."""
    ids = [line.split()[1] for line in output.splitlines()
           if line.startswith(("FAILED ", "ERROR ")) and len(line.split()) > 1]
    return " ".join(ids)


def round_order(builds, round_number: int) -> list:
    """The builds in the order of this round: as given in odd rounds, reversed in even ones."""
    return list(builds) if round_number % 2 else list(reversed(builds))


def run_suite(tree: Path, log: Path) -> dict:
    """The README's test command in `tree` with an empty Taichi cache (a fresh HOME); its
    output (stdout, then stderr) goes to `log`, whose name the row keeps: a failure's traceback
    is there to read (one that the table only named took a rerun to explain, 2026-12-03)."""
    with tempfile.TemporaryDirectory(prefix="suite_home_") as home:
        started = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider"],
                             cwd=tree, capture_output=True, text=True,
                             env={**os.environ, "HOME": home, "PYTHONPATH": str(tree)})
        wall = time.perf_counter() - started
    log.write_text(run.stdout + run.stderr)
    return {"wall_s": wall, "returncode": run.returncode, **last_line_figures(run.stdout),
            "failed_tests": failed_tests(run.stdout), "log": log.name}


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--before", required=True, help="baseline commit")
    parser.add_argument("--after", default="HEAD", help="commit measured against it")
    parser.add_argument("--rounds", type=int, default=2, help="interleaved rounds (>= 1)")
    parser.add_argument("--out", required=True, help="folder for suite.csv")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds must be >= 1, got {args.rounds}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    builds = {"before": commit_of(args.before), "after": commit_of(args.after)}
    rows = []
    machine = machine_columns("cpu")
    with tempfile.TemporaryDirectory() as scratch:
        shared = REPO.parent / "shared"
        if shared.is_dir():
            (Path(scratch) / "shared").symlink_to(shared)
        trees = {build: worktree(commit, Path(scratch)) for build, commit in builds.items()}
        try:
            for round_number in range(1, args.rounds + 1):
                for build in round_order(builds, round_number):
                    print(f"round {round_number}, {build} ({builds[build]})", flush=True)
                    rows.append({"build": build, "commit": builds[build], "round": round_number,
                                 **run_suite(trees[build],
                                             out / f"suite_{build}_round{round_number}.log"),
                                 **machine})
                    print(f"  {rows[-1]['wall_s']:.1f} s", flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=REPO,
                               capture_output=True)
    table = pd.DataFrame(rows)
    table.to_csv(out / "suite.csv", index=False)
    (out / "suite.csv.json").write_text(json.dumps({
        "study": "suite_builds", "command": "python tools/suite_builds.py " + shlex.join(argv),
        "description": f"the test suite with an empty Taichi cache, {args.rounds} interleaved "
                       f"rounds (before: {builds['before']}, after: {builds['after']})",
        "git_commit": builds["after"],
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")},
        indent=1))
    print(table.to_string(index=False))


if __name__ == "__main__":
    main()
