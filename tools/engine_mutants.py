"""Hand-made mutants of the engine, each run against the tests meant to kill it: the mutation
check that mutmut cannot do for Taichi kernels (they compile per process and do not survive its
fork). For each mutant: a fresh copy of the committed tree (git worktree at HEAD), one textual
change, the named tests with `-x`; killed when they fail (after a control run in which every
named test passes unmutated). Writes a CSV (one row per mutant) and its provenance sidecar.

    python tools/engine_mutants.py [--out results/mutation/engine_mutants.csv] [--only M1,M3]
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
RELIABILITY = "tests/model/test_reliability.py::"

MUTANTS = [
    # (id, file, original text, mutated text, tests that should kill it, what it breaks)
    ("M1", "taichi_star/engine.py", "halvings <= self.max_substep_halvings[None]",
     "halvings < self.max_substep_halvings[None]",
     [RELIABILITY + "test_no_substep_halvings_still_takes_every_benign_step"],
     "the substep loop stops one halving early"),
    ("M2", "taichi_star/engine.py", "        if halvings > 0:\n            self.state.substep_retries",
     "        if halvings > 1:\n            self.state.substep_retries",
     [RELIABILITY + "test_substep_retries_counts_exactly_the_steps_the_full_step_could_not_take"],
     "substep_retries under-counted"),
    ("M3", "taichi_star/engine.py", "error_left <= self.newton_tol[None]",
     "error_left <= 10.0 * self.newton_tol[None]",
     [RELIABILITY + "test_engine_newton_stops_within_newton_tol_after_the_references_iterations"],
     "the engine's Newton stopping rule 10x loose"),
    ("M4", "taichi_star/integrators.py",
     "predictor += h * (velocity - previous_velocity)",
     "predictor += 0.0 * h * (velocity - previous_velocity)",
     [RELIABILITY + "test_newton_iterations_of_a_fixed_scenario_stay_in_their_band"],
     "Newton's start loses the carried acceleration (more iterations, same result)"),
    ("M5", "taichi_star/engine.py",
     "error_left = ti.min(error_left, contraction / (1.0 - contraction) * largest_update)",
     "error_left = ti.min(error_left, largest_update)",
     [RELIABILITY + "test_newton_iterations_of_a_fixed_scenario_stay_in_their_band"],
     "the contraction estimate dropped (one more confirming iteration)"),
    ("M6", "taichi_star/engine.py", "self.state.steps_done[b] >= self.step_limit[None]",
     "self.state.steps_done[b] > self.step_limit[None]",
     [RELIABILITY + "test_an_adaptive_robot_stops_at_the_step_limit_or_a_step_that_cannot_advance"],
     "the adaptive step limit one step late"),
    ("M7", "taichi_star/actuation.py", "late = rows[~(clock[rows] < at)]",
     "late = rows[~(clock[rows] <= at)]",
     ["tests/model/test_simulator.py::test_bad_durations_times_and_foreign_states_are_refused"],
     "fire(at_s=now) accepted (and lost)"),
]


def pytest(tests, worktree: Path) -> subprocess.CompletedProcess:
    """The tests, stopping at the first failure, on the worktree's code."""
    return subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-n", "0",
                           "-p", "no:cacheprovider", *tests], cwd=worktree,
                          capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(worktree)})


def run(mutant, worktree: Path) -> dict:
    ident, path, original, mutated, tests, what = mutant
    target = worktree / path
    source = target.read_text()
    if source.count(original) != 1:
        raise SystemExit(f"{ident}: the text to mutate is not found once in {path}")
    target.write_text(source.replace(original, mutated))
    start = time.perf_counter()
    try:
        result = pytest(tests, worktree)
    finally:
        target.write_text(source)
    return {"mutant": ident, "file": path, "what": what, "tests": " ".join(tests),
            "outcome": "killed" if result.returncode != 0 else "survived",
            "seconds": round(time.perf_counter() - start, 1)}


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/mutation/engine_mutants.csv")
    parser.add_argument("--only", default="", help="comma list of mutant ids (default: all)")
    args = parser.parse_args()
    chosen = [m for m in MUTANTS if not args.only or m[0] in args.only.split(",")]
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory(prefix="engine_mutants_") as scratch:
        worktree = Path(scratch) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(worktree), "HEAD"], cwd=REPO,
                       check=True, capture_output=True)
        try:
            # the control: unmutated, every test must pass, or a "kill" would mean nothing
            control = pytest(sorted({test for m in chosen for test in m[4]}), worktree)
            if control.returncode != 0:
                raise SystemExit(f"the tests fail without a mutant:\n{control.stdout[-2000:]}")
            for mutant in chosen:
                row = {**run(mutant, worktree), "commit": commit}
                print(f"{row['mutant']} {row['outcome']:<8} {row['seconds']:6.1f} s  {row['what']}",
                      flush=True)
                rows.append(row)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(worktree)], cwd=REPO,
                           capture_output=True)
    out = REPO / args.out
    out.parent.mkdir(parents=True, exist_ok=True)
    with out.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    sidecar = {"command": "python tools/engine_mutants.py " + " ".join(sys.argv[1:]),
               "git_commit": subprocess.run(["git", "rev-parse", "HEAD"], cwd=REPO,
                                            capture_output=True, text=True).stdout.strip(),
               "date": time.strftime("%Y-%m-%dT%H:%M:%S+00:00", time.gmtime())}
    out.with_name(out.name + ".json").write_text(json.dumps(sidecar, indent=2) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
