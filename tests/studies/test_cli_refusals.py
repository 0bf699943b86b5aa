"""Study-specific flags refused on the command line before any compute and before the output
folder is made: one line naming the flag and its range, exit code 2, no traceback (each case
crashed with a traceback, started work that could not finish, repeated work listed twice, or
refused only after making the output folder). Also what a refused or finished run leaves: no
output folder after an unreachable --scheduler, no library's INFO log on stderr."""

import logging
import warnings

import pytest

from taichi_star import MAX_STEPS_PER_INSTANCE, SolverConfig
from taichi_star.driver import check_run

from studies import cli
from studies.__main__ import main as studies_main

QUICK = ["--quick", "--no-progress"]
STEP_LIMIT = "the limit is 2147483647 steps per instance"


@pytest.mark.parametrize("study, argv, message", [
    ("bench", ["--plain-duration", "0"], "--plain-duration must be in [0.001, 100] s, got 0.0"),
    ("bench", ["--sensitivity-duration", "nan"], "--sensitivity-duration must be in [0.001, 100]"),
    ("convergence", ["--n-arc", "500,1000,2000"], "--n-arc: n_arc must be an integer in [2, 1000]"),
    ("env_bench", ["--control-period", "1e12"],
     "--control-period: control_period_s = 1e+12 s at dt = 0.005 s is 2e+14 time steps"),
    ("env_bench", ["--steps", "1000000000"], "--steps 1000000000 (+1 compiling)"),
    ("gait_design", ["--direction", "nan"],
     "--direction must be an angle in [-360, 360] deg, got nan"),
    # an angle of 1e300 deg was wrapped to some direction; a turn has none (it was ignored)
    ("gait_design", ["--direction=-360.5"],
     "--direction must be an angle in [-360, 360] deg, got -360.5"),
    ("gait_design", ["--goal", "turn", "--direction", "45"],
     "--direction: only with --goal speed (turning has no direction)"),
    # a reach tolerance at the goals' distance: every goal counted as reached before a move
    ("strokes", ["--window", "0"], "--window must be in (0, 1.575] s (half the period), got 0"),
    ("strokes", ["--window", "1.6"], "--window must be in (0, 1.575] s (half the period)"),
    ("strokes", ["--cycles", "2"], "--cycles must be a whole number >= 3 (the fit's cycles 1-3)"),
    ("strokes", ["--cycles", "3.5"], "--cycles must be a whole number >= 3"),
    ("strokes", ["--set", "period=3.2"], "--set period: set by the strokes study itself"),
    ("plan", ["--tolerance", "50", "--distance", "50"],
     "--tolerance must be below --distance (50 mm), got 50"),
    ("plan", ["--tolerance", "30", "--directions", "0", "--far", "30"],
     "--tolerance must be below --far (30 mm), got 30"),
    # the last --set of a field won without a word; a swept field's --set was dropped
    ("fig4c", ["--set", "alpha=0.5", "--set", "alpha=0.9"], "--set alpha: given twice"),
    # a flag of one value given twice: argparse kept the last, and the first's values were
    # dropped without a word (an audit, 2026-12); both spellings, and in any study
    ("sweep", ["--gaits", "A1", "--alpha", "0.4,0.5", "--alpha", "0.8"],
     "--alpha given twice (the second would replace the first): give it once"),
    ("sweep", ["--gaits", "A1", "--alpha=0.4", "--alpha", "0.8"], "--alpha given twice"),
    # the robots' derivatives are checked with the grid, before the output folder
    ("sweep", ["--gaits", "A1", "--sensitivities", "alpah"],
     "--sensitivities: sensitivities: 'alpah' is not a StarParams field; did you mean alpha?"),
    ("sweep", ["--gaits", "A1", "--sensitivities", "alpha,hub_height"],
     "--sensitivities: sensitivities: hub_height is 0 (the 2.5-D model off) for instance 0"),
    ("sensitivity", ["--seed", "1", "--seed", "2"], "--seed given twice"),
    ("gradient_fit", ["--sets", "6", "--sets", "20"], "--sets given twice"),
    # a setting of fits all left out was taken and unused without a word (an audit, 2026-12)
    ("gradient_fit", ["--lm-batch", "3", "--lm-iterations", "0", "--lm-broyden-iterations", "0"],
     "--lm-batch 3: unused, --lm-iterations and --lm-broyden-iterations at 0 leave out every fit"),
    ("gradient_fit", ["--lm-broyden-batch", "2", "--lm-broyden-iterations", "0"],
     "--lm-broyden-batch 2: unused, --lm-broyden-iterations at 0 leave out every fit it sets"),
    ("gradient_fit", ["--least-squares-method", "dogbox", "--least-squares-evaluations", "0",
                      "--broyden-evaluations", "0"],
     "--least-squares-method dogbox: unused, --least-squares-evaluations, --broyden-evaluations "
     "and --polish-evaluations at 0"),
    # a per-actuator field's eight values were read as eight values of an axis, each refused
    # as "got 1" entry (an audit, 2026-12)
    ("sweep", ["--gaits", "A1", "--param", "actuator_gains=1,1,0.5,1,1,1,1,1"],
     "--param actuator_gains: a per-actuator field (eight values, A1..A8, a robot) is not an "
     "axis of a sweep: give it to every instance with --set actuator_gains=1,1,0.5,1,1,1,1,1"),
    # each said "parameter given twice", the gait's when it was given once (an audit, 2026-12)
    ("sweep", ["--param", "gait=A1,A1+A2"],
     "--param gait: the gait axis is --gaits (e.g. --gaits A1,A1+A2)"),
    ("sweep", ["--gaits", "A1", "--alpha", "0.5,0.6", "--param", "alpha=1,2"],
     "--param alpha: swept by --alpha already (give its values once)"),
    ("sweep", ["--gaits", "A1", "--param", "alpha=0.5", "--param", "alpha=1,2"],
     "--param alpha: given twice"),
    ("sweep", ["--gaits", "A1", "--alpha", "0.5,0.6", "--set", "alpha=0.9"],
     "--set alpha: swept as well (fix it or sweep it, not both)"),
    ("sweep", ["--gaits", "A1+A2", "--set", "gait=A1"],
     "--set gait: swept as well (fix it or sweep it, not both)"),
    ("model_select", ["--candidates", " "], "--candidates: an empty file name"),
    # a value that is no number named no range, where the API's message does
    ("fig4c", ["--set", "alpha=nan"],
     "--set alpha: 'nan' is not a finite number (alpha must be in [0, 10])"),
    ("sweep", ["--gaits", "A1", "--alpha", "0.5,x"],
     "--alpha: 'x' is not a number (alpha must be in [0, 10])"),
    # a value out of its range named no flag ("invalid parameter value: ..."), an audit
    ("sweep", ["--gaits", "A1", "--alpha", "0,50"],
     "--alpha: alpha must be a real number in [0, 10], got 50.0"),
    ("sweep", ["--gaits", "A1", "--param", "drag_parallel=0,-1"],
     "--param drag_parallel: drag_parallel must be a real number in [0, 100], got -1.0"),
    # each value fits the base model alone (a joint radius of 0.025 m, a tip at 0.0245 m),
    # not together: the flags of the combination are named
    ("sweep", ["--gaits", "A1", "--param", "joint_radius=0.02,0.025", "--param",
               "tip_radius=0.0245"],
     "--gaits, --param joint_radius, --param tip_radius together: tip_radius must be a real "
     "number in (0.025, 2] (beyond joint_radius: the limbs point outwards), got 0.0245"),
    ("stability", ["--alphas", "0.5,50"],
     "--alphas: alpha must be a real number in [0, 10], got 50.0"),
    ("fig4c", ["--set", "actuator_gains=1,1,1,1,1,1,1,nan"],
     "--set actuator_gains: 'nan' is not a finite number (actuator_gains must be 8 numbers in "
     "[0, 5])"),
    ("gait_design", ["--seed", "-1"], "--seed must be >= 0, got -1"),
    # --quick runs whole --cycles here, not --quick's 0.2 s
    ("gait_design", ["--cycles", "1000000000"], "--cycles 1000000000 (3.15e+09 s)"),
    ("plan", ["--max-cycles", "1000000000"], "--max-cycles 1000000000 + --settle-cycles 1"),
    ("plan", ["--lookahead-gaits", "A1,A2"], "--lookahead-gaits: only with --lookahead"),
    ("plan", ["--resume"], "--resume: only with --lookahead"),
    ("plan", ["--lookahead", "--lookahead-gaits", "A1,A9"], "--lookahead-gaits: "),
    # within the planner's step counter, past it with the lookahead's coasts
    ("plan", ["--lookahead", "--max-cycles", "2000000"],
     "--lookahead: max_cycles = 2000000 decisions of 2 periods"),
    ("plan", ["--glide-cycles", "1000000000"], "--cycles 2 + --glide-cycles 1000000000"),
    ("primitives", ["--glide-cycles", "1000000000"], "--cycles 2 + --glide-cycles 1000000000"),
    ("calibrate", ["--restarts", "11"], "--restarts must be <= 10"),
    ("model_select", ["--restarts", "1000000"], "--restarts must be <= 10"),
    ("gradient_fit", ["--seed", "-1"], "--seed must be >= 0, got -1"),
    # SALib seeds nothing for 0: another sample and other intervals at every run
    ("sensitivity", ["--seed", "0"], "--seed must be >= 1, got 0"),
    ("sensitivity_check", ["--parameters", "bogus"], "--parameters: sensitivities: 'bogus'"),
    ("sensitivity_check", ["--duration", "1e12"], "--duration 1e+12 s at dt = 0.001 s"),
    ("sensitivity_check", ["--duration", "1e-9"], "--duration 1e-09 s is less than one step"),
    ("simd", ["--matmul-size", "10000000"], "--matmul-size must be in [16, 8192], got 10000000"),
    ("sweep", ["--max-instances", "0"], "--max-instances must be in [1, 1000000] (the most "
                                        "instances a study runs), got 0"),
    ("sweep", ["--max-instances", "1000001"], "--max-instances must be in [1, 1000000]"),
    # four axes of 65,536 points and five gaits (2^64 × 5): NumPy's int64 product wrapped and
    # the run started
    ("sweep", ["--alpha", "0.2:1.2:65536", "--added-mass", "0:2:65536", "--youngs-modulus",
               "2e6:1e7:65536", "--param", "drag_parallel=0:0.1:65536"],
     "the product has 92233720368547758080 instances, more than --max-instances 1000000"),
    # a fit's generations and population: a billion generations ran, a population of a
    # billion ran out of memory in cma
    ("calibrate", ["--max-generations", "1000000000"],
     "--max-generations 1000000000 × the population (4, doubled at each of --restarts 0) × 5 "
     "gaits: 20,000,000,000 instances, more than the 1,000,000 a study runs"),
    ("calibrate", ["--popsize", "1000000000"], "instances, more than the 1,000,000 a study runs"),
    # a cross-validation's fold fits the other gaits (counted as all of them, an audit)
    ("calibrate", ["--cross-validate", "--gaits", "A1,A1+A2", "--fit", "alpha=0.5:2",
                   "--popsize", "500", "--max-generations", "1001"],
     "--max-generations 1001 × the population (500, doubled at each of --restarts 0) × 1 gaits "
     "(and the held-out one's prediction) × 2 folds: 1,001,004 instances"),
    ("gradient_fit", ["--cma-generations", "1000000000"],
     "instances, more than the 1,000,000 a study runs"),
    ("gradient_fit", ["--lbfgs-evaluations", "1000000000"],
     "instances, more than the 1,000,000 a study runs"),
    # a sample that would not fit in memory (224 GiB), counted before it is drawn
    ("sensitivity", ["--base-samples", "1073741824"],
     "--base-samples 1073741824: 85,899,345,920 instances (1073741824 × (14 + 2) points × 5 "
     "gaits), more than the 1,000,000 a study runs"),
    ("sweep", ["--alpha", "0:1:10000000000"],
     "--alpha: range '0:1:10000000000' has 10000000000 points; at most 1000000"),
    # as many processes as asked for would be started
    ("scaling", ["--workers-list", "100000"],
     "--workers-list: every value must be in [1, 256], got 100000"),
    ("bench", ["--workers-list", "1,100000"],
     "--workers-list: every value must be in [1, 256], got 100000"),
    ("sweep", ["--workers", "100000"], "--workers must be in [1, 256], got 100000"),
    # a value listed twice would only be measured or fitted twice
    ("scaling", ["--workers-list", "1,1"], "--workers-list: 1 is listed twice in '1,1'"),
    ("bench", ["--workers-list", "1,1"], "--workers-list: 1 is listed twice in '1,1'"),
    ("bench", ["--lanes", "auto,auto"], "--lanes: 'auto' is listed twice in 'auto,auto'"),
    ("gradient_fit", ["--sets", "6,6"], "--sets: '6' is listed twice in '6,6'"),
    # measurements and searches that could not finish
    ("bench", ["--steps", "2000000000"], "--steps must be in [1, 100000], got 2000000000"),
    ("bench", ["--scenario-batch", "1000000000"],
     "--scenario-batch must be in [1, 1048576], got 1000000000"),
    ("bench", ["--batch-sizes", "8,2000000000"],
     "--batch-sizes: every value must be in [1, 1048576], got 2000000000"),
    ("env_bench", ["--num-envs", "100000000"], "--num-envs must be in [1, 1048576], got 100000000"),
    ("gait_design", ["--synchronous-starts", "1000000"],
     "--synchronous-starts must be in [1, 255], got 1000000"),
    ("gait_design", ["--random-starts", "1000000"],
     "--random-starts must be in [0, 1000], got 1000000"),
    ("gait_design", ["--iterations", "1000000000"],
     "--iterations must be in [1, 1000], got 1000000000"),
    ("plan", ["--directions", "100000"], "--directions must be in [0, 360], got 100000"),
    # a goal past a metre (metrics.MAX_GOAL_MM); 1e308 ran every plan, then failed plotting
    ("plan", ["--distance", "1000.5"], "--distance must be in (0, 1000] mm, got 1000.5"),
    ("plan", ["--far", "1000.5"], "--far must be in [0, 1000] mm, got 1000.5"),
    ("bench", ["--repeats", "101"], "--repeats must be in [1, 100], got 101"),
    # each flag within its range, the whole past what can finish: it started silently
    ("bench", ["--batch-sizes", "1048576", "--steps", "100000", "--repeats", "100"],
     "the batch section (--batch-sizes summing to 1,048,576 robots, 10 warm-up + --steps "
     "100000, --repeats 100, 1 setting(s)) is 1.05e+13 robot-steps"),
    ("simd", ["--repeats", "1000000"], "--repeats must be in [1, 100], got 1000000"),
    # within the range, past any memory: NumPy's MemoryError (a traceback) after the folder
    ("simd", ["--batch-sizes", "1048576"],
     "--batch-sizes: 1,048,576 paper systems of factor_solve in 4 forms would need about 609 "
     "GiB of memory"),
    # the assemblies alone were not checked (an audit, 2026-12)
    ("simd", ["--batch-sizes", "1048576", "--kernels", "bending"],
     "--batch-sizes: 1,048,576 paper systems of bending in 4 forms would need about 446 GiB"),
    ("simd", ["--batch-sizes", "1048576", "--kernels", "rod_drag"],
     "--batch-sizes: 1,048,576 paper systems of rod_drag in 4 forms would need about 496 GiB"),
    ("jacobians", ["--rounds", "1000000"], "--rounds must be in [1, 100], got 1000000"),
    ("jacobians", ["--batch", "2000000000"], "--batch must be in [1, 1048576], got 2000000000"),
    ("animate", ["--frames", "1000000000"], "--frames must be in [2, 10000], got 1000000000"),
    ("animate", ["--frames", "10001"], "--frames must be in [2, 10000], got 10001"),
    # the library's GIF bound (it was checked after the run: a traceback, the tables left)
    ("animate", ["--fps", "51"], "--fps must be in [1, 50], got 51"),
    ("jacobians", ["--modes", "bogus"],
     "--modes: 'bogus' is not MODE:TOL (MODE one of newton, chord, lagged, TOL Newton's "
     "tolerance in m, e.g. lagged:1e-10)"),
    # work that could not finish, counted before any instance is built: a model selection had
    # no cap (a population of a million started CMA-ES), jacobians counted no rounds (3e11
    # robot-steps started silently) and stability built a grid of three million for a minute
    ("model_select", ["--only", "ramp", "--gaits", "A1", "--popsize", "1000000",
                      "--max-generations", "1000000", "--fold-generations", "0",
                      "--refine-top", "0"],
     "1 candidate(s) × 1 gait(s) × --max-generations 1000000 × --popsize 1000000 (doubled at "
     "each of --restarts 0), with --fold-generations 0 per held-out gait and the --refine-top 0 "
     "refitted at --refine-generations 3 × --refine-popsize 4: 1,000,000,000,000 instances, "
     "more than the 1,000,000 a study runs"),
    # one past the cap (101 × 9901); 1000 × 1000 is accepted below
    ("model_select", ["--only", "ramp", "--gaits", "A1", "--popsize", "101",
                      "--max-generations", "9901", "--fold-generations", "0", "--refine-top", "0"],
     "--popsize 101 (doubled at each of --restarts 0), with --fold-generations 0 per held-out "
     "gait and the --refine-top 0 refitted at --refine-generations 3 × --refine-popsize 4: "
     "1,000,001 instances"),
    # the folds and the refine stage count: the screens alone are 2 × 2 × 249 × 1000 = 996,000
    # instances; the folds add 2 × 2 × (1 × 1000 × 1 + 1) and the refine stage (--quick: the
    # top 1 at 3 generations of 4) 3 × 4 × 2 + 2 × (1 × 4 × 1 + 1)
    ("model_select", ["--popsize", "1000", "--max-generations", "249"],
     "2 candidate(s) × 2 gait(s) × --max-generations 249 × --popsize 1000 (doubled at each of "
     "--restarts 0), with --fold-generations 1 per held-out gait and the --refine-top 1 "
     "refitted at --refine-generations 3 × --refine-popsize 4: 1,000,038 instances"),
    # --quick's modes: the default (newton:1e-10), lagged:1e-10 and the reference
    ("jacobians", ["--batch", "5000", "--duration", "100", "--rounds", "100"],
     "--batch 5000 × --rounds 100 × 3 configurations (--modes, with the default and the "
     "reference): 1,500,000 instances, more than the 1,000,000 a study runs"),
    # two configurations (the default and the reference): 500,000 is accepted below
    ("jacobians", ["--batch", "500001", "--rounds", "1", "--modes", "newton:1e-10"],
     "--batch 500001 × --rounds 1 × 2 configurations (--modes, with the default and the "
     "reference): 1,000,002 instances"),
    ("stability", ["--stiffness", "0.5:2:1000", "--alphas", "0:1:1000", "--added-mass", "0,1,5",
                   "--dts-ms", "1", "--periods", "3.15", "--precisions", "f64", "--gaits", "A1"],
     "--dts-ms 1 × --stiffness 1000 × --alphas 1000 × --added-mass 3 × --periods 1 × --gaits 1 "
     "× --precisions 1: 3,000,000 instances, more than the 1,000,000 a study runs"),
    # one past the cap (101 × 9901); 1000 × 1000 is accepted below
    ("stability", ["--stiffness", "1:2:101", "--alphas", "0:1:9901", "--added-mass", "1",
                   "--dts-ms", "1", "--periods", "3.15", "--precisions", "f64", "--gaits", "A1"],
     "--dts-ms 1 × --stiffness 101 × --alphas 9901 × --added-mass 1 × --periods 1 × --gaits 1 "
     "× --precisions 1: 1,000,001 instances"),
    # bench's bounds: the most instances of one engine, the most lanes of one
    ("simd", ["--batch-sizes", "16,1048577"],
     "--batch-sizes: every value must be in [1, 1048576], got 1048577"),
    ("simd", ["--lanes", "4,17"], "--lanes: every value must be in [1, 16], got 17"),
])
def test_study_flags_are_refused_before_the_output_folder(no_compute, tmp_path, capsys, study,
                                                          argv, message):
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert message in error and len(error.strip().splitlines()) == 1, error
    assert "Traceback" not in error
    assert not out.exists()


class PastTheFlagChecks(Exception):
    """The study got past its flags' checks (the next step is stubbed: nothing runs)."""


def past_the_flag_checks(*args, **kwargs):
    """A stand-in for a study's first step after its flags' checks: it raises
    PastTheFlagChecks."""
    raise PastTheFlagChecks


@pytest.mark.parametrize("study, argv, next_step", [
    ("plan", ["--distance", "1000"], "studies.cli.default_goals"),
    ("plan", ["--far", "1000"], "studies.cli.default_goals"),
    ("animate", ["--frames", "10000"], "studies.cli.resolve_gaits"),
    ("plan", ["--tolerance", "49.99", "--distance", "50"], "studies.cli.default_goals"),
    ("plan", ["--tolerance", "29.99", "--directions", "0", "--far", "30"],
     "studies.cli.default_goals"),
    ("gait_design", ["--direction=-360"], "studies.cli.check_cycles"),
    ("gait_design", ["--direction", "360"], "studies.cli.check_cycles"),
    ("model_select", ["--only", "ramp", "--gaits", "A1", "--popsize", "1000",
                      "--max-generations", "1000", "--fold-generations", "0", "--refine-top", "0"],
     "taichi_star.identification.measured_trials"),
    ("jacobians", ["--batch", "500000", "--rounds", "1", "--modes", "newton:1e-10"],
     "studies.cli.paper_gaits_batch"),
    ("stability", ["--stiffness", "0.5:2:1000", "--alphas", "0:1:1000", "--added-mass", "1",
                   "--dts-ms", "1", "--periods", "3.15", "--precisions", "f64", "--gaits", "A1"],
     "studies.cli.base_params"),
    ("simd", ["--batch-sizes", "1048576", "--lanes", "16"], "studies.simd.elimination_plans"),
])
def test_study_flags_at_the_end_of_their_range_are_accepted(no_compute, monkeypatch, tmp_path,
                                                            study, argv, next_step):
    """The closed ends of the ranges the refusals above name: a goal of exactly a metre
    (--distance, --far: (0, 1000] and [0, 1000] mm), 10,000 frames, exactly the 1,000,000
    instances a study runs and bench's largest batch and lanes get past the flag checks to the
    study's next step (stubbed, so nothing is built or run)."""
    monkeypatch.setattr(next_step, past_the_flag_checks)
    out = tmp_path / "out"
    with pytest.raises(PastTheFlagChecks):
        studies_main([study, *argv, "--out", str(out), *QUICK])
    assert not out.exists()


@pytest.mark.parametrize("heights, expected", [
    ([], False),
    (["--set", "hub_height=0.02", "--set", "foam_height=0.02", "--set", "actuator_height=0.02"],
     True)])
def test_sweep_sensitivities_all_are_the_models_differentiable_fields(no_compute, monkeypatch,
                                                                     tmp_path, heights,
                                                                     expected):
    """`sweep --sensitivities all`: every differentiable field, per-actuator ones as their
    eight, less the component heights where the model has them at 0 (with them, "all" was
    refused for the paper's robot, whose heights are 0)."""
    from taichi_star import DIFFERENTIABLE_FIELDS
    from studies import sweep
    asked = []

    def stop(directions, grid, solver):
        asked.extend(direction.label for direction in directions)
        raise PastTheFlagChecks
    monkeypatch.setattr(sweep, "check_defined", stop)
    with pytest.raises(PastTheFlagChecks):
        studies_main(["sweep", "--gaits", "A1", "--sensitivities", "all", *heights,
                      "--out", str(tmp_path / "out"), *QUICK])
    assert ("hub_height" in asked) is expected and "alpha" in asked
    # the two per-actuator fields as eight numbers each, the three heights where set
    assert len(asked) == len(DIFFERENTIABLE_FIELDS) - 2 + 2 * 8 - (0 if expected else 3)


def test_an_engine_that_would_not_fit_is_refused_before_the_output_folder(no_compute, tmp_path,
                                                                          monkeypatch, capsys):
    """env_bench's most robots (1,048,576: ~116 GiB of engine) ran two minutes, then failed
    with a traceback and left its folder (an audit); with 8 GiB available now one line."""
    from taichi_star import runtime
    monkeypatch.setattr(runtime, "available_memory_bytes", lambda: 8 * 2**30)
    out = tmp_path / "out"
    assert studies_main(["env_bench", "--num-envs", "1048576", "--out", str(out), *QUICK]) == 2
    error = capsys.readouterr().err
    assert ("--num-envs: params: an engine and model of 1,048,576 instances would need about "
            in error) and len(error.strip().splitlines()) == 1
    assert not out.exists()


FULL = ["--no-progress"]
"""A full run's flags (not --quick, whose 0.2 s replaces --cycles and the run's own length)."""
STEP_LIMIT_END = f"{STEP_LIMIT} (the int32 step counter)"
"""How a refusal of a run past the step limit ends."""
# --cycles of a 1000-s period at 1 ms: 2147.483647 are the step limit's 2147483647 steps
# (rounded), 2147.483648 one step more
PAST_THE_LONGEST = ["--cycles", "2147.483648"]
AT_THE_LONGEST = ["--cycles", "2147.483647"]


@pytest.mark.parametrize("study, argv, message", [
    # a period that varies per instance was checked at the model's own (3.15 s): the library
    # refused the run with a traceback, calibrate's after CMA-ES had started
    ("sweep", ["--gaits", "A1", "--period", "900", "--cycles", "1e4"],
     "--cycles 10000 of the longest period, 900 s (9e+06 s) at dt = 0.001 s is 9e+09 time "
     "steps per instance; " + STEP_LIMIT_END),
    ("sweep", ["--gaits", "A1", "--period", "2,1000", *PAST_THE_LONGEST],
     "--cycles 2147.48 of the longest period, 1000 s (2.15e+06 s) at dt = 0.001 s is 2.15e+09 "
     "time steps per instance; " + STEP_LIMIT_END),
    # half a step (0.5 ms of 1 ms) rounds to none, as the library rounds (half to even)
    ("sweep", ["--gaits", "A1", "--period", "0.5,3.15", "--cycles", "0.001"],
     "--cycles 0.001 of the shortest period, 0.5 s (0.0005 s) is less than one step "
     "(dt = 0.001 s)"),
    ("sensitivity", ["--gaits", "A1", "--base-samples", "2", "--vary", "period=900:1000",
                     "--dt", "0.001", *PAST_THE_LONGEST],
     "--cycles 2147.48 of the longest period, 1000 s (2.15e+06 s) at dt = 0.001 s is 2.15e+09 "
     "time steps per instance; " + STEP_LIMIT_END),
    ("calibrate", ["--gaits", "A1", "--fit", "period=900:1000", "--popsize", "2",
                   "--max-generations", "1", *PAST_THE_LONGEST],
     "--cycles 2147.48 of the longest period, 1000 s (2.15e+06 s) at dt = 0.001 s is 2.15e+09 "
     "time steps per instance; " + STEP_LIMIT_END),
    # only the upper bound was checked: a progress bar, then a traceback
    ("work_precision", ["--cycles", "1e-9"],
     "--cycles 1e-09 (3.15e-09 s) is less than one step (the grid's coarsest step 0.004 s)"),
    # 0.00063492 of 3.15 s are 0.49999995 steps of 4 ms: none once rounded
    ("work_precision", ["--cycles", "0.00063492"],
     "--cycles 0.00063492 (0.002 s) is less than one step (the grid's coarsest step 0.004 s)"),
    # scaling has no --cycles, and cli.solver checked no run: the library's traceback
    ("scaling", ["--no-dask", "--dt", "1e-9"],
     "the sweep's cycle (3.15 s) at --dt 1e-09 s is 3.15e+09 time steps per instance; "
     + STEP_LIMIT_END),
    # 3.15 s / 1.46683e-9 s are 2147488121 steps, past the limit
    ("scaling", ["--no-dask", "--dt", "1.46683e-9"],
     "the sweep's cycle (3.15 s) at --dt 1.46683e-09 s is 2.15e+09 time steps per instance; "
     + STEP_LIMIT_END),
    # model_select has no --cycles: its windows' 6 cycles were not checked (a traceback, with
    # CMA-ES's bar drawn); 18.9 s / 8.80099e-9 s are 2147485681 steps, past the limit
    ("model_select", ["--dt", "8.80099e-9"],
     "--train-cycles, --validate-cycles (6 cycles of the longest period, 3.15 s: 18.9 s) at "
     "dt = 8.80099e-09 s is 2.15e+09 time steps per instance; " + STEP_LIMIT_END),
])
def test_run_lengths_are_refused_before_the_output_folder(no_compute, tmp_path, capsys, study,
                                                          argv, message):
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--out", str(out), *FULL]) == 2
    error = capsys.readouterr().err
    assert error.strip().endswith(message) and len(error.strip().splitlines()) == 1, error
    assert not out.exists()


@pytest.mark.parametrize("study, argv, next_step", [
    ("sweep", ["--gaits", "A1", "--period", "2,1000", *AT_THE_LONGEST],
     "studies.cli.param_product"),
    # 0.50005 steps: one once rounded
    ("sweep", ["--gaits", "A1", "--period", "0.5,3.15", "--cycles", "0.0010001"],
     "studies.cli.param_product"),
    ("sensitivity", ["--gaits", "A1", "--base-samples", "2", "--vary", "period=900:1000",
                     "--dt", "0.001", *AT_THE_LONGEST], "studies.cli.Output"),
    ("calibrate", ["--gaits", "A1", "--fit", "period=900:1000", "--popsize", "2",
                   "--max-generations", "1", *AT_THE_LONGEST], "studies.cli.Output"),
    # 0.50000029 steps of 4 ms: one once rounded
    ("work_precision", ["--cycles", "0.000634921"], "studies.cli.Output"),
    # 2147473480 steps
    ("scaling", ["--no-dask", "--dt", "1.46684e-9"], "studies.cli.Output"),
    # 2147483241 steps
    ("model_select", ["--dt", "8.801e-9"], "studies.cli.Output"),
])
def test_run_lengths_at_the_end_of_their_range_are_accepted(no_compute, monkeypatch, tmp_path,
                                                            study, argv, next_step):
    """The last run lengths the refusals above accept get past the checks to the study's next
    step (stubbed: nothing is built or run)."""
    monkeypatch.setattr(next_step, past_the_flag_checks)
    out = tmp_path / "out"
    with pytest.raises(PastTheFlagChecks):
        studies_main([study, *argv, "--out", str(out), *FULL])
    assert not out.exists()


ADAPTIVE = SolverConfig(adaptive=True, dt_max=0.05, dt_min=1e-6, dt=1e-3)
RECORD_S = 1e-5


@pytest.mark.parametrize("duration_s, record_interval_s, refused", [
    # an audit's case: 3e9 step ends at a record every 10 µs; the study counted 6e5 of dt_max
    (3.0e4, RECORD_S, True),
    (3.0e4, 0.0, False),                               # no records: steps of dt_max
    (3.0e4, ADAPTIVE.dt_max, False),                   # records as far apart as dt_max: same
    (MAX_STEPS_PER_INSTANCE * RECORD_S, RECORD_S, False),        # the limit's step itself
    ((MAX_STEPS_PER_INSTANCE + 1) * RECORD_S, RECORD_S, True),   # one record past it
])
def test_check_run_counts_steps_as_the_library_does(duration_s, record_interval_s, refused):
    """cli.check_run refuses a run exactly when the library would (`fewest_steps`, also
    driver.check_run's count): with adaptive steps and records closer than dt_max, a step per
    record."""
    def outcome(check, error):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # the long-run estimate
            try:
                check()
            except error as raised:
                return str(raised)
        return None

    library = outcome(lambda: check_run(ADAPTIVE, duration_s, record_interval_s, batch=1),
                      ValueError)
    study = outcome(lambda: cli.check_run("--duration", duration_s, ADAPTIVE, record_interval_s),
                    cli.StudyArgumentError)
    assert (library is not None, study is not None) == (refused, refused)
    if refused:
        assert study.startswith(f"--duration at a record every {RECORD_S:g} s, each a step "
                                f"end is ") and STEP_LIMIT in study, study


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


@pytest.mark.parametrize("resume", [False, True])
def test_plan_keeps_a_lookahead_checkpoint_it_cannot_continue(no_compute, tmp_path, capsys,
                                                               resume):
    """A checkpoint in --out: without --resume it is not written over; with it, one the
    lookahead refuses (here no checkpoint at all) is named. Both before any compute."""
    checkpoint = tmp_path / "resume" / "lookahead.npz"
    checkpoint.parent.mkdir()
    checkpoint.write_bytes(b"not a checkpoint")
    assert studies_main(["plan", "--lookahead", "--out", str(tmp_path), *QUICK,
                         *(["--resume"] if resume else [])]) == 2
    error = capsys.readouterr().err
    expected = (f"--resume: checkpoint '{checkpoint}': not a lookahead's checkpoint" if resume
                else f"--out {tmp_path} holds an unfinished lookahead ({checkpoint}): --resume "
                     f"continues it; remove that file to start afresh")
    assert expected in error and len(error.strip().splitlines()) == 1, error
    assert checkpoint.read_bytes() == b"not a checkpoint"


def test_reproduce_refuses_a_result_listed_twice(tmp_path, capsys):
    assert studies_main(["reproduce", "--only", "sweep,sweep", "--into", str(tmp_path / "into"),
                         "--dry-run"]) == 2
    error = capsys.readouterr().err
    assert "--only: 'sweep' is listed twice in 'sweep,sweep'" in error, error
    assert len(error.strip().splitlines()) == 1


def test_an_installed_package_without_results_asks_for_into_and_names_inputs_to_make(
        tmp_path, capsys, monkeypatch):
    """An installed package has no committed results/ (`cli.COMMITTED_RESULTS` is then a folder
    in site-packages that is not there): reproduce wrote into it by default, where an
    uninstall left it, and elasticities and gait_design failed naming a default table there
    (an audit, 2026-12). reproduce needs --into, also where such a run left a results/ folder
    there, and a default table that is not there is refused naming the study that makes it;
    --dry-run needs no extra."""
    from studies import EXTRA_OF_STUDY, reproduce

    missing = tmp_path / "site-packages" / "taichi_star" / "results"
    monkeypatch.setattr(reproduce, "COMMITTED_RESULTS", missing)
    monkeypatch.setattr(cli, "COMMITTED_RESULTS", missing)
    assert cli.in_checkout() is False
    assert studies_main(["reproduce", "--dry-run"]) == 2
    missing.mkdir(parents=True)  # made by an earlier reproduce into site-packages
    assert studies_main(["reproduce", "--dry-run"]) == 2
    capsys.readouterr()
    missing.rmdir()
    assert studies_main(["reproduce", "--dry-run"]) == 2
    error = capsys.readouterr().err.strip()
    assert error == (f"python -m studies reproduce: error: --into: needed outside a checkout of "
                     f"the repository (the committed results/ are not here, {missing}): give a "
                     f"folder, e.g. --into runs/reproduce")
    assert studies_main(["reproduce", "--dry-run", "--into", str(tmp_path / "into")]) == 0
    assert not missing.exists() and EXTRA_OF_STUDY["reproduce"] is None
    for flag, made_by in (("--sobol", "sensitivity"), ("--primitives", "primitives")):
        default = missing / "table.csv"
        with pytest.raises(cli.StudyArgumentError, match=(
                rf"^{flag} {default}: not here \(the committed results/ come with a checkout "
                rf"of the repository, not with an installed package\): make one with "
                rf"`python -m studies {made_by}` and give its table as {flag}$")):
            cli.committed_input(default, flag, made_by)
    # a table the user names, wherever it is, is read (or refused) as it is
    assert cli.committed_input(tmp_path / "mine.csv", "--sobol", "sensitivity") == \
        str(tmp_path / "mine.csv")


def test_an_installed_command_names_itself_in_usage_messages_and_recorded_commands(
        monkeypatch):
    """An installed package recorded `python -m studies ...` in its files and its usage, which
    it does not have: the `taichi-star` command names itself (an audit, 2026-12)."""
    from studies import provenance

    monkeypatch.setattr("sys.argv", ["/usr/local/bin/taichi-star", "fig4c", "--quick"])
    assert provenance.record("fig4c", ["--quick"])["command"] == "taichi-star fig4c --quick"
    assert cli.StudyParser("fig4c", "the main job").prog == "taichi-star fig4c"


def test_reproduce_refuses_an_into_that_is_a_file(tmp_path, capsys):
    """--into was not checked: the first study refused it, then reproduce added a traceback."""
    into = tmp_path / "a_file"
    into.write_text("")
    assert studies_main(["reproduce", "--only", "fig4c", "--into", str(into)]) == 2
    error = capsys.readouterr().err
    assert f"--into {into}: exists and is not a folder" in error
    assert len(error.strip().splitlines()) == 1


@pytest.mark.parametrize("into, message", [
    # Path("") is the current folder: hours of results written wherever the shell stood
    ("", "--into: an empty folder name"),
    # below a file: the first study refused it after reproduce had printed its command
    ("a_file/results", "a_file/results: cannot write into"),
])
def test_reproduce_refuses_an_into_it_could_not_write_before_any_study(tmp_path, capsys,
                                                                        monkeypatch, into,
                                                                        message):
    (tmp_path / "a_file").write_text("")
    monkeypatch.chdir(tmp_path)
    assert studies_main(["reproduce", "--only", "fig4c", "--into", into]) == 2
    captured = capsys.readouterr()
    assert message in captured.err and len(captured.err.strip().splitlines()) == 1
    assert captured.out == ""  # no study's command printed, none started


@pytest.mark.parametrize("run_dir, message", [
    # --quick wrote its chunks into the committed results/ through --run-dir
    (cli.COMMITTED_RESULTS / "chunks_of_a_quick_run",
     "--quick runs never write into the committed results/"),
    ("a_file", "exists and is not a folder"),
    ("a_file/chunks", "cannot write into"),
])
def test_a_run_store_folder_is_checked_before_any_compute(no_compute, tmp_path, capsys,
                                                          monkeypatch, run_dir, message):
    (tmp_path / "a_file").write_text("")
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert studies_main(["sweep", "--gaits", "A1", "--run-dir", str(run_dir), "--out", str(out),
                         *QUICK]) == 2
    error = capsys.readouterr().err
    assert f"--run-dir {run_dir}: {message}" in error, error
    assert len(error.strip().splitlines()) == 1
    assert not out.exists() and not (cli.COMMITTED_RESULTS / "chunks_of_a_quick_run").exists()


def test_reproduce_stops_at_a_failed_study_in_one_line_with_its_status(tmp_path, capsys,
                                                                       monkeypatch):
    """A study that fails (it says why itself) ended reproduce in a CalledProcessError
    traceback, exit 1 (an audit, 2026-12): one line naming it, its exit status passed on, the
    studies after it not run. The command runs this package's studies (`studies` here,
    `taichi_star.studies` once installed: `python -m studies` failed there)."""
    import subprocess

    from studies import reproduce

    ran = []

    def failing(line, **kwargs):
        ran.append(line)
        return subprocess.CompletedProcess(line, 3)
    monkeypatch.setattr(subprocess, "run", failing)
    into = tmp_path / "into"
    assert studies_main(["reproduce", "--only", "fig4c,convergence", "--into", str(into)]) == 3
    error = capsys.readouterr().err
    assert error.strip() == "reproduce: fig4c failed (exit status 3); the results written " \
                            "before it are kept"
    assert len(ran) == 1 and ran[0][1:4] == ["-m", reproduce.__package__, "fig4c"]


def unreachable_scheduler(**settings):
    """executor_for of a --scheduler that does not answer (after its timeout, 30 s)."""
    raise ValueError("scheduler: cannot reach tcp://127.0.0.1:9: Timed out trying to connect")


@pytest.mark.parametrize("study, argv", [
    ("sweep", []),
    ("gaits", []),
    # it writes its sample before the run: a small one (SALib's import is most of the time)
    ("sensitivity", ["--vary", "alpha=0.4:1.2", "--gaits", "A1"]),
])
def test_an_unreachable_scheduler_leaves_no_output_folder(no_compute, monkeypatch, tmp_path,
                                                          capsys, study, argv):
    monkeypatch.setattr(cli, "executor_for", unreachable_scheduler)
    out = tmp_path / "out"
    assert studies_main([study, *argv, "--scheduler", "tcp://127.0.0.1:9", "--out", str(out),
                         *QUICK]) == 2
    error = capsys.readouterr().err
    assert "--scheduler: cannot reach tcp://127.0.0.1:9" in error, error
    assert len(error.strip().splitlines()) == 1 and not out.exists()


def test_an_unreachable_scheduler_keeps_an_output_folder_that_was_there(no_compute, monkeypatch,
                                                                        tmp_path):
    monkeypatch.setattr(cli, "executor_for", unreachable_scheduler)
    out = tmp_path / "out"
    out.mkdir()
    assert studies_main(["sweep", "--scheduler", "tcp://127.0.0.1:9", "--out", str(out),
                         *QUICK]) == 2
    assert out.is_dir()


def test_library_info_logs_stay_off_stderr(monkeypatch, capsys):
    """Dask's distributed sets its loggers to INFO and logs every connection closed at a
    cluster's shutdown with its traceback (the scaling study printed them): the studies show
    warnings and errors only."""
    root = logging.getLogger()
    monkeypatch.setattr(root, "handlers", [])  # as in a fresh `python -m studies`
    monkeypatch.setattr(root, "level", root.level)
    cli.configure_logging()
    chatty = logging.getLogger("distributed.batched")
    monkeypatch.setattr(chatty, "level", logging.INFO)
    try:
        raise ConnectionError("the client left")
    except ConnectionError:
        chatty.info("Batched Comm Closed", exc_info=True)
    logging.getLogger("taichi_star.batch").warning("a damaged chunk is recomputed")
    assert capsys.readouterr().err == "a damaged chunk is recomputed\n"


@pytest.mark.parametrize("study, argv, message", [
    ("fig4c", ["--set", "alpha="], "--set alpha: empty value list"),
    ("sweep", ["--gaits", "A1", "--param", "alpha=0.5,0.5"],
     "--param alpha: 0.5 is listed twice in '0.5,0.5' (give each value once)"),
])
def test_a_field_range_is_named_for_a_value_that_is_no_number_only(no_compute, tmp_path, capsys,
                                                                    study, argv, message):
    """The range is what a value that is no number needs; an empty list or a repeated value
    is another mistake, whose message stays as it was (a review, 2026-12)."""
    assert studies_main([study, *argv, "--out", str(tmp_path / "out"), *QUICK]) == 2
    error = capsys.readouterr().err.strip()
    assert error.endswith(message), error


def study_gaits_flags():
    """(study, the help of its --gaits flag, or animate's --gait) of every study that has
    one."""
    import importlib
    import studies
    flags = []
    for name in studies.study_names():
        try:
            parser = importlib.import_module(f"studies.{name}").build_parser()
        except (ImportError, AttributeError):
            continue
        flags += [(name, action.help)
                  for action in parser._actions
                  if {"--gaits", "--gait"} & set(action.option_strings)]
    return flags


def test_every_gaits_flag_names_what_it_accepts(no_compute, tmp_path, capsys):
    """A --gaits flag read by `cli.resolve_gaits` accepts paper, all and a list, and its help
    names the three (sensitivity's, animate's and four others' left out "all", which they
    took); one
    that fits the measured gaits says so, and refuses "all" naming the gait that is not
    measured, before any compute."""
    flags = study_gaits_flags()
    assert {"sweep", "sensitivity", "gradient_fit", "animate"} <= {study for study, _ in flags}
    for study, text in flags:
        if "measured" in text:
            assert studies_main([study, "--gaits", "all", "--out", str(tmp_path / study),
                                 *QUICK]) == 2
            assert "A2: not measured" in capsys.readouterr().err, study
        else:
            assert all(form in text for form in ("paper", "all", "comma list")), (study, text)


@pytest.mark.parametrize("study", ["elasticities", "sensitivity", "sensitivity_check"])
def test_a_study_of_speeds_or_derivatives_refuses_the_gait_that_fires_nothing(no_compute,
                                                                            tmp_path, capsys,
                                                                            study):
    """--gaits none ran to tables whose every speed, derivative and elasticity was empty,
    with NumPy's and matplotlib's warnings (an audit, 2026-12); a list holding it is refused
    too, and a gait that fires is taken (the same list without it)."""
    for gaits in ("none", "A1+A3,none"):
        out = tmp_path / study
        assert studies_main([study, "--gaits", gaits, "--out", str(out), *QUICK]) == 2
        error = capsys.readouterr().err
        assert error.count("\n") == 1 and "--gaits: 'none' fires no actuator" in error, error
        assert not out.exists()
    assert cli.resolve_gaits("A1+A3", firing=True) == ["A1+A3"]
    assert cli.resolve_gaits("none") == ["none"]  # where a resting robot is a case of its own


def test_a_run_too_large_for_memory_is_one_line_naming_the_flag(monkeypatch, tmp_path, capsys):
    """animate with more frames than memory holds ended in the library's ValueError with a
    traceback and exit 1 (an audit, 2026-12): the memory refusal (`MemoryBudgetError`, before
    any compute) is one line naming --frames, exit 2, and no folder is made; any study's such
    refusal is one line too."""
    import taichi_star.runtime
    monkeypatch.setattr(taichi_star.runtime, "available_memory_bytes", lambda: 1e5)
    out = tmp_path / "out"
    assert studies_main(["animate", "--out", str(out), *QUICK]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1
    assert lines[0].startswith("python -m studies animate: error: --frames 60 of 1 gait(s) "
                               "over 0.2 s: record_interval_s: the summary and ")
    assert "would need about" in lines[0] and not out.exists()
    assert studies_main(["fig4c", "--out", str(out), *QUICK]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and "would need about" in lines[0] and not out.exists()


@pytest.fixture
def committed(monkeypatch, tmp_path):
    """A stand-in for the committed results/, holding one committed table."""
    results = tmp_path / "results"
    results.mkdir()
    (results / "jacobians.csv").write_text("committed\n")
    monkeypatch.setattr(cli, "COMMITTED_RESULTS", results.resolve())
    return results


def test_a_run_into_the_committed_results_with_other_flags_is_refused(no_compute, committed,
                                                                      capsys):
    """A small run with --out results/ replaced the committed tables without a word (an audit,
    2026-12): refused before the folder is touched, one line naming --out and reproduce's own
    flags for the study; the committed file is left as it was."""
    argv = ["jacobians", "--batch", "1", "--duration", "0.001", "--out", str(committed)]
    assert studies_main(argv) == 2
    error = capsys.readouterr().err
    assert len(error.strip().splitlines()) == 1 and "Traceback" not in error
    assert (f"--out {committed}: holds committed results, which only `python -m studies "
            f"reproduce` replaces (its runs of jacobians: no flags); this run's flags "
            f"(--batch 1 --duration 0.001) differ: give another --out, or "
            f"--replace-committed to replace them") in error
    assert [p.name for p in committed.iterdir()] == ["jacobians.csv"]
    assert (committed / "jacobians.csv").read_text() == "committed\n"


@pytest.mark.parametrize("study, flags, where, taken", [
    # reproduce's own runs into results/ itself, whatever --out and --no-progress say
    ("jacobians", [], ".", True),
    ("jacobians", ["--no-progress"], ".", True),
    ("fig4c", ["--preset", "accurate", "--prefix", "fig4c_accurate"], ".", True),
    ("calibrate", ["--preset", "accurate", "--cross-validate"], ".", True),
    # other flags, or reproduce's in another order (another command line), are refused
    ("fig4c", ["--preset", "accurate"], ".", False),
    ("fig4c", ["--prefix", "fig4c_accurate", "--preset", "accurate"], ".", False),
    ("jacobians", ["--rounds", "1"], ".", False),
    # with --replace-committed any run; another run into a folder in results/ only when it is
    # new or empty; reproduce's into one that holds files (`reproduce --into results/sub`: its
    # second study writes beside its first's, and was refused after the first's hours; a
    # review, 2026-12)
    ("jacobians", ["--rounds", "1", "--replace-committed"], ".", True),
    ("jacobians", ["--rounds", "1"], "new", True),
    ("jacobians", ["--rounds", "1"], "empty", True),
    ("jacobians", ["--rounds", "1"], "full", False),
    ("jacobians", [], "full", True),
    ("jacobians", [], "../outside", True),
])
def test_only_reproduces_runs_or_a_run_that_means_it_write_into_committed_results(
        committed, study, flags, where, taken):
    (committed / "empty").mkdir()
    (committed / "full").mkdir()
    (committed / "full" / "table.csv").write_text("committed\n")
    folder = committed / where
    argv = [*flags, "--out", str(folder)]
    replace = "--replace-committed" in flags
    if taken:
        cli.check_committed_folder(folder, study, argv, replace)
    else:
        with pytest.raises(cli.StudyArgumentError, match=r"holds committed results"):
            cli.check_committed_folder(folder, study, argv, replace)
