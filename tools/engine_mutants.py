"""Hand-made mutants of the engine, each run against the tests meant to kill it: the mutation
check that mutmut cannot do for Taichi kernels (they compile per process and do not survive its
fork). For each mutant: a fresh copy of the committed tree (git worktree at HEAD), one textual
change, the named tests with `-x`; killed when one of them fails (its exception recorded: an
assertion, or what else stopped it), "error" when pytest stops otherwise (after a control run
in which every named test passes unmutated). Writes a CSV (one row per mutant) and its
provenance sidecar.

    python tools/engine_mutants.py [--out results/mutation/engine_mutants.csv] [--only M1,M3]

Without --out the table goes to a fresh runs/engine_mutants/<time>/, so a partial run never
overwrites the committed one; it is rewritten after every mutant, so an interrupted run keeps
what it measured. A mutant whose tests have not ended within --timeout-s counts as "timeout".
"""

import argparse
import csv
import io
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from taichi_star.provenance import code_record, table_stamp, write_atomic

REPO = Path(__file__).resolve().parents[1]
RELIABILITY = "tests/model/test_reliability.py::"
LAGGED = "tests/model/test_lagged_jacobian.py::"
SENSITIVITIES = "tests/model/test_sensitivities.py::"
ADAPTIVE = "tests/model/test_adaptive.py::"

MUTANTS = [
    # (id, file, original text, mutated text, tests that should kill it, what it breaks)
    ("M1", "taichi_star/engine.py", "if halvings > self.max_substep_halvings[None]:",
     "if halvings >= self.max_substep_halvings[None]:",
     [RELIABILITY + "test_no_substep_halvings_still_takes_every_benign_step",
      RELIABILITY + "test_substep_retries_counts_exactly_the_steps_the_full_step_could_not_take"],
     "the substep loop stops one halving early"),
    ("M2", "taichi_star/engine.py", "        if halvings > 0:\n            self.state.substep_retries",
     "        if halvings > 1:\n            self.state.substep_retries",
     [RELIABILITY + "test_substep_retries_counts_exactly_the_steps_the_full_step_could_not_take"],
     "substep_retries under-counted"),
    ("M3", "taichi_star/engine.py", "largest_update <= self.newton_tol[None]",
     "largest_update <= 10.0 * self.newton_tol[None]",
     [RELIABILITY + "test_engine_newton_stops_within_newton_tol_after_the_references_iterations"],
     "the engine's Newton stopping rule 10x loose"),
    ("M4", "taichi_star/integrators.py",
     "predictor += h * (velocity - previous_velocity)",
     "predictor += 0.0 * h * (velocity - previous_velocity)",
     [RELIABILITY + "test_newton_iterations_of_a_fixed_scenario_stay_in_their_band"],
     "Newton's start loses the carried acceleration (more iterations, same result)"),
    ("M5", "taichi_star/engine.py", "largest_update <= self.newton_tol[None]",
     "largest_update * ti.min(1.0, largest_update / ti.max(previous_update, 1e-300)) "
     "<= self.newton_tol[None]",
     [RELIABILITY + "test_every_accepted_step_is_within_newton_tol_of_its_solution"],
     "a contraction estimate θ·|Δ_k| accepted again (steps stopped short of newton_tol)"),
    ("M6", "taichi_star/engine.py", "self.state.steps_done[b] >= self.step_limit[None]",
     "self.state.steps_done[b] > self.step_limit[None]",
     [RELIABILITY + "test_an_adaptive_robot_stops_at_the_step_limit_or_a_step_that_cannot_advance"],
     "the adaptive step limit one step late"),
    ("M7", "taichi_star/actuation.py", "late = rows[~(clock[rows] < at)]",
     "late = rows[~(clock[rows] <= at)]",
     ["tests/model/test_simulator.py::test_bad_durations_times_and_foreign_states_are_refused"],
     "fire(at_s=now) accepted (and lost)"),
    ("M8", "taichi_star/engine.py", "self.kept_age[b] < LAGGED_MAX_AGE",
     "self.kept_age[b] <= LAGGED_MAX_AGE",
     [LAGGED + "test_a_kept_factorisation_is_reused_for_its_age_limit_and_then_refactored"],
     "the lagged Jacobian keeps a factorisation one solve past its age limit"),
    ("M9", "taichi_star/engine.py",
     "and self.kept_inertia_scale[b] == inertia_scale \\\n"
     "                and self.kept_rate_gain[b] == rate_gain and",
     "and self.kept_inertia_scale[b] > 0.0 and",
     [LAGGED + "test_a_factorisation_is_reused_only_with_the_same_integrator_weights"],
     "the lagged Jacobian reuses a factorisation made with other integrator weights"),
    ("M10", "taichi_star/engine.py", "iterations > LAGGED_KEEP_MAX_UPDATES",
     "iterations >= LAGGED_KEEP_MAX_UPDATES",
     [LAGGED + "test_a_solve_of_many_updates_or_a_failed_one_leaves_nothing_to_reuse",
      LAGGED + "test_in_a_run_two_updates_keep_and_three_do_not"],
     "a solve of exactly LAGGED_KEEP_MAX_UPDATES updates drops its factorisation"),
    ("M11", "taichi_star/engine.py",
     "if converged == 0 or iterations > LAGGED_KEEP_MAX_UPDATES:",
     "if iterations > LAGGED_KEEP_MAX_UPDATES:",
     [LAGGED + "test_a_failed_solve_leaves_nothing_to_reuse"],
     "a failed solve's factorisation kept for reuse"),
    ("M12", "taichi_star/engine.py", "scale[changed] = 0.0", "scale[:] = 0.0",
     [LAGGED + "test_putting_back_some_instances_leaves_the_others_bitwise_alone"],
     "resetting some robots drops every robot's kept factorisation"),
    ("M13", "taichi_star/engine.py", "if changed is not None and changed.any():",
     "if False:",
     [LAGGED + "test_putting_back_some_instances_leaves_the_others_bitwise_alone"],
     "a reset robot goes on with the factorisation of the state it left"),
    ("M14", "taichi_star/engine.py",
     "                self.rigid_correction(b, centre, wanted_force, wanted_torque,\n"
     "                                      inertia_scale * total_mass, inertia_scale * moment)\n",
     "",
     [SENSITIVITIES + "test_a_glide_does_not_drift_the_tangents_rigid_motion"],
     "the tangent step without its rigid-motion correction"),
    ("M15", "taichi_star/engine.py", "if self.same_as_instance[b, k] == 0:",
     "if self.same_as_instance[b, k] == 1:",
     [SENSITIVITIES + "test_euler_sensitivities_equal_finite_differences"],
     "the replicas leave out the terms they differ in, not those they share"),
    ("M16", "taichi_star/stepping.py", "elif limit - end < 0.25 * proposed:",
     "elif limit - end <= 0.25 * proposed:",
     ["tests/unit/test_stepping.py::test_step_end"],
     "a step that leaves exactly a quarter step before its stop is split"),
    ("M17", "taichi_star/engine.py",
     "                    self.state.status[r] = self.state.status[b]\n", "",
     [SENSITIVITIES + "test_a_failed_instance_has_no_derivatives_and_leaves_its_neighbour_alone"],
     "a failed instance's replicas keep status ok (finite derivatives of a frozen run)"),
    ("M18", "taichi_star/stepping.py", "    if end >= limit - slack:",
     "    if end > limit - slack:",
     ["tests/unit/test_stepping.py::test_step_end"],
     "a step that would end exactly on its stop is split instead"),
    ("M19", "taichi_star/engine.py",
     "                    if ti.static(self.integrator.order == 2) and use_history == 1:\n"
     "                        error *= 2.0\n", "",
     [ADAPTIVE + "test_adaptive_results_do_not_depend_on_batch_position"],
     "a rejected BDF2 step redone without history is sized as a BDF2 step"),
    ("M20", "taichi_star/engine.py",
     "                self.state.rejected_steps[b] = self.state.rejected_steps[b] + 1\n"
     "                self.state.history_valid[b] = 0\n",
     "                self.state.rejected_steps[b] = self.state.rejected_steps[b] + 1\n",
     [ADAPTIVE + "test_adaptive_results_do_not_depend_on_batch_position"],
     "a rejected step's redo keeps BDF2's history"),
    ("M21", "taichi_star/engine.py", "            if due >= 0.0 and due <= target:",
     "            if due >= 0.0 and due < target:",
     [ADAPTIVE + "test_adaptive_results_do_not_depend_on_batch_position"],
     "an adaptive step ending exactly on a firing is not treated as the firing's"),
    ("M22", "taichi_star/engine.py",
     "                self.state.velocities[plus, n] = self.implicit_velocity(plus, n, rate_gain)\n",
     "", [SENSITIVITIES + "test_euler_sensitivities_equal_finite_differences"],
     "a replica's velocities not moved with its positions"),
    ("M23", "taichi_star/stepping.py", "return error <= tol or at_smallest(h, proposed, dt_min)",
     "return error < tol or at_smallest(h, proposed, dt_min)",
     ["tests/unit/test_stepping.py::test_accepts"],
     "a step whose error is exactly the tolerance is redone"),
    ("M24", "taichi_star/stepping.py", "return ti.min(h, proposed) <= dt_min",
     "return ti.min(h, proposed) < dt_min", ["tests/unit/test_stepping.py::test_accepts"],
     "a step at exactly dt_min over the tolerance is redone at dt_min again, forever"),
    ("M25", "taichi_star/stepping.py", "return error <= tol or at_smallest(h, proposed, dt_min)",
     "return error <= tol", ["tests/unit/test_stepping.py::test_accepts"],
     "no step is kept over the tolerance, even at dt_min (the adaptive loop never ends)"),
    ("M26", "taichi_star/engine.py", "            store.write(kept)\n", "            pass\n",
     [LAGGED + "test_putting_back_some_instances_leaves_the_others_bitwise_alone"],
     "a lagged snapshot's kept factorisations not put back (the continuation refactors)"),
    ("M27", "taichi_star/engine.py", "moving = self.state.fire_time[b, actuator] >= 0.0",
     "moving = self.state.fire_time[b, actuator] > 0.0",
     [SENSITIVITIES + "test_an_actuator_the_gait_never_fires_has_no_influence"],
     "a pair waiting for an actuator fired at t = 0 waits until its next firing"),
    ("M28", "taichi_star/engine.py", "moving = self.state.fire_time[b, actuator] >= 0.0",
     "moving = False",
     [SENSITIVITIES + "test_a_direction_waiting_for_its_actuator_wakes_exact_when_it_fires"],
     "a waiting pair never wakes"),
    ("M29", "taichi_star/engine.py",
     "                shift = ti.Vector.zero(float, 2)\n                if moving:\n",
     "                shift = ti.Vector.zero(float, 2)\n                if True:\n",
     [SENSITIVITIES + "test_an_actuator_the_gait_never_fires_has_no_influence"],
     "a waiting pair moved by the right-hand side its instance's previous pair left"),
    ("M30", "taichi_star/engine.py",
     "np.where(actuator == actuator[partner_rows], actuator, -1)", "actuator",
     ["tests/model/test_engine.py::"
      "test_a_replica_pair_waits_for_the_actuator_whose_gain_or_delay_alone_it_moves"],
     "a pair waits though its replicas differ in different actuators' columns"),
    ("M31", "taichi_star/engine.py", "single = ~elsewhere & (columns.sum(axis=1) == 1)",
     "single = columns.sum(axis=1) == 1",
     ["tests/model/test_engine.py::"
      "test_a_replica_pair_waits_for_the_actuator_whose_gain_or_delay_alone_it_moves"],
     "a pair waits though it also differs in a coefficient read before any firing"),
    ("M32", "taichi_star/engine.py", "single = ~elsewhere & (columns.sum(axis=1) == 1)",
     "single = ~elsewhere & (columns.sum(axis=1) >= 1)",
     ["tests/model/test_engine.py::"
      "test_a_replica_pair_waits_for_the_actuator_whose_gain_or_delay_alone_it_moves"],
     "a pair waits for one actuator though it differs in two actuators' columns"),
    ("M33", "taichi_star/engine.py", "moving = self.state.fire_time[b, actuator] >= 0.0",
     "moving = self.state.fire_time[plus, actuator] >= 0.0",
     [SENSITIVITIES + "test_waiting_pairs_keep_every_bit_of_pairs_that_do_not_wait"],
     "a pair wakes a step late (its replica's fire time, copied after this test)"),
    ("M34", "taichi_star/engine.py",
     "                self.prepare_step(r, start_time, end_time, h, ratio, use_history, 0)\n",
     "                if moving:\n"
     "                    self.prepare_step(r, start_time, end_time, h, ratio, use_history, 0)\n",
     [SENSITIVITIES + "test_waiting_pairs_keep_every_bit_of_pairs_that_do_not_wait"],
     "a waiting pair skips its preparation too (6e-9 off once it wakes)"),
]


def pytest(tests, worktree: Path,
           timeout_s: float | None) -> subprocess.CompletedProcess | None:
    """The tests, stopping at the first failure, on the worktree's code; None when they have
    not ended within timeout_s (None: no limit)."""
    try:
        # -m "": the named tests run whatever their mark (the slow tier's too)
        return subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-n", "0", "-m", "",
                               "-p", "no:cacheprovider", *tests], cwd=worktree,
                              capture_output=True, text=True, timeout=timeout_s,
                              env={**os.environ, "PYTHONPATH": str(worktree)})
    except subprocess.TimeoutExpired:
        return None


def run(mutant, worktree: Path, timeout_s: float) -> dict:
    ident, path, original, mutated, tests, what = mutant
    target = worktree / path
    source = target.read_text()
    target.write_text(source.replace(original, mutated))
    start = time.perf_counter()
    try:
        result = pytest(tests, worktree, timeout_s)
    finally:
        target.write_text(source)
    failure = "" if result is None else first_failure(result.stdout)
    if result is None:
        # a mutant that hangs its tests is not killed by them: they never fail
        outcome = "timeout"
    elif result.returncode == 0:
        outcome = "survived"
    else:
        # a kill is a named test failing; anything else (a collection error, a crash) says
        # nothing about the tests' strength
        outcome = "killed" if failure else "error"
    return {"mutant": ident, "file": path, "what": what, "tests": " ".join(tests),
            "outcome": outcome, "failure": failure,
            "seconds": round(time.perf_counter() - start, 1)}


def first_failure(output: str) -> str:
    """The exception that failed the first failed test, from the traceback's last line
    ("tests/x.py:50: AssertionError" gives "AssertionError"); "" when no test failed."""
    if not any(line.startswith("FAILED ") for line in output.splitlines()):
        return ""
    raised = re.search(r"^\S+\.py:\d+: (\w+)", output, re.MULTILINE)
    return raised.group(1) if raised else "unknown"


def write_table(rows, out: Path, argv=None):
    """The rows so far as a CSV at out, with its provenance sidecar, each written whole or not
    at all (a kill while the table is rewritten leaves the previous one). The sidecar: the
    command (`argv`, default this process's, quoted as a shell reads it back: it was joined
    with spaces, so that an argument with a space read as two; an audit, 2026-12), the code
    record (commit, whether the checkout was dirty, the date) and the table's stamp."""
    out.parent.mkdir(parents=True, exist_ok=True)
    table = io.StringIO(newline="")
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    data = table.getvalue().encode()
    write_atomic(out, data)
    argv = sys.argv[1:] if argv is None else argv
    sidecar = {"command": "python tools/engine_mutants.py " + shlex.join(argv), **code_record(),
               **table_stamp(len(rows), data)}
    write_atomic(out.with_name(out.name + ".json"),
                 (json.dumps(sidecar, indent=2, default=str) + "\n").encode())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=None,
                        help="the table's path (default: runs/engine_mutants/<time>/)")
    parser.add_argument("--only", default="", help="comma list of mutant ids (default: all)")
    parser.add_argument("--timeout-s", type=float, default=1200.0,
                        help="the most seconds one mutant's tests may run (default 1200)")
    args = parser.parse_args()
    chosen = [m for m in MUTANTS if not args.only or m[0] in args.only.split(",")]
    if not chosen:
        parser.error(f"--only {args.only!r} names no mutant (M1-M{len(MUTANTS)})")
    if args.timeout_s <= 0:
        parser.error(f"--timeout-s must be > 0, got {args.timeout_s:g}")
    out = REPO / (args.out or f"runs/engine_mutants/{time.strftime('%Y%m%d-%H%M%S')}"
                              "/engine_mutants.csv")
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True, check=True).stdout.strip()
    rows = []
    with tempfile.TemporaryDirectory(prefix="engine_mutants_") as scratch:
        worktree = Path(scratch) / "tree"
        subprocess.run(["git", "worktree", "add", "--detach", str(worktree), "HEAD"], cwd=REPO,
                       check=True, capture_output=True)
        try:
            missing = [f"{ident} ({path})" for ident, path, original, *_ in chosen
                       if (worktree / path).read_text().count(original) != 1]
            if missing:
                raise SystemExit(f"the text to mutate is not found once for {', '.join(missing)}")
            # the control: unmutated, every test must pass, or a "kill" would mean nothing
            control = pytest(sorted({test for m in chosen for test in m[4]}), worktree, None)
            if control.returncode != 0:
                raise SystemExit(f"the tests fail without a mutant:\n{control.stdout[-2000:]}")
            for mutant in chosen:
                row = {**run(mutant, worktree, args.timeout_s), "commit": commit}
                print(f"{row['mutant']} {row['outcome']:<8} {row['seconds']:6.1f} s  {row['what']}",
                      flush=True)
                rows.append(row)
                write_table(rows, out)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(worktree)], cwd=REPO,
                           capture_output=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
