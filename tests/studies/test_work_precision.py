"""The work-precision study in --quick mode: its speeds against a direct `simulate`, its
Richardson limits and errors recomputed from the speeds in its own CSV, the summary against the
rows; and the extrapolation helpers on exact power laws. No timing is asserted. The whole
run's robot-steps checked before any run."""

import math
import warnings

import numpy as np
import pandas as pd
import pytest

import taichi_star
from taichi_star import timegrid

from studies import cli
from studies import work_precision as wp
from studies.__main__ import main as studies_main

FLOOR_MM_S = 0.5


def ladder_limit(speeds):
    """Richardson limit of a (levels, gaits) ladder, coarse to fine, refined by 2 per level:
    the observed order of the three finest from the largest changes over the gaits, at least
    1."""
    coarse, middle, fine = speeds[-3:]
    order = math.log2(np.abs(coarse - middle).max() / np.abs(middle - fine).max())
    order = max(order, 1.0)
    return fine + (fine - middle) / (2.0 ** order - 1.0)


def error(speed, reference):
    return np.abs(speed - reference) / np.maximum(np.abs(reference), FLOOR_MM_S)


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("work_precision")
    wp.main(["--quick", "--no-progress", "--out", str(out)])
    return out


@pytest.mark.slow
def test_quick_rows_and_a_direct_simulation(quick_run):
    rows = pd.read_csv(quick_run / "work_precision.csv")
    summary = pd.read_csv(quick_run / "work_precision_summary.csv")
    gaits = list(wp.QUICK_GAITS)
    configs = wp.configurations(wp.QUICK_GRID)
    assert len(rows) == len(configs) * len(gaits) and len(summary) == len(configs)
    assert (rows["status"] == "ok").all()
    assert rows.groupby("config")["gait"].apply(list).map(lambda g: g == gaits).all()
    # the accurate preset simulated directly
    config = wp.preset_config("damped")
    direct = taichi_star.simulate(config.params(gaits), wp.QUICK_DURATION_S,
                                  config.solver).summary
    accurate = rows[rows["preset"] == "accurate"]
    assert list(accurate["label"].unique()) == [config.label()]
    assert accurate["signed_speed_mm_s"].to_numpy() == pytest.approx(
        direct["signed_speed_mm_s"].to_numpy(), rel=1e-9)
    assert accurate["steps"].tolist() == direct["steps"].tolist()
    assert (quick_run / "work_precision.png").stat().st_size > 1000


@pytest.mark.slow
def test_quick_limits_and_errors_recomputed_from_the_speeds(quick_run):
    rows = pd.read_csv(quick_run / "work_precision.csv")
    gaits = list(wp.QUICK_GAITS)
    grid = wp.QUICK_GRID
    for model, preset in wp.MODEL_PRESETS.items():
        part = rows[rows["model"] == model]
        mesh = int(part.loc[part["preset"] == preset, "n_arc"].iloc[0])
        bdf2 = part[(part["integrator"] == "bdf2") & (part["stepping"] == "fixed")]
        on_mesh = bdf2[bdf2["n_arc"] == mesh].pivot(index="h_ms", columns="gait",
                                                    values="signed_speed_mm_s")[gaits]
        time_limit = ladder_limit(on_mesh.sort_index(ascending=False).to_numpy())
        at_space_step = bdf2[bdf2["h_ms"] == grid.space_h_ms].pivot(
            index="n_arc", columns="gait", values="signed_speed_mm_s")[gaits].sort_index()
        # the space ladder, and the preset mesh (in the ladder or not) at the ladder's step
        assert set(at_space_step.index) == set(grid.n_arcs[model]) | {mesh}
        space_limit = ladder_limit(at_space_step.loc[list(grid.n_arcs[model])].to_numpy())
        continuum = space_limit + time_limit - at_space_step.loc[mesh].to_numpy()
        for _, config in part.groupby("config"):
            speed = config["signed_speed_mm_s"].to_numpy()
            # the CSV keeps 10 significant digits (a written limit is within 5e-10 of the
            # study's; the speeds it is recomputed from are too): 1e-9 relative, where 2.5e-10
            # is seen
            assert config["continuum_limit_mm_s"].to_numpy() == pytest.approx(continuum,
                                                                              rel=1e-9)
            # the CSV keeps 10 significant digits (~1e-9 mm/s on these speeds): an error
            # recomputed from written speeds matches to 1e-8 of the 0.5-mm/s floor, whatever
            # its size (a run within 1e-4 of its limit has no 6 digits to compare)
            assert config["total_error"].to_numpy() == pytest.approx(error(speed, continuum),
                                                                     rel=1e-6, abs=1e-8)
            if config["n_arc"].iloc[0] == mesh:
                # 10 significant digits, as the continuum limit above
                assert config["time_limit_mm_s"].to_numpy() == pytest.approx(time_limit,
                                                                             rel=1e-9)
                assert config["time_error"].to_numpy() == pytest.approx(
                    error(speed, time_limit), rel=1e-6, abs=1e-8)
            else:
                assert config["time_error"].isna().all()
            space_series = (config["integrator"].iloc[0] == "bdf2"
                            and config["stepping"].iloc[0] == "fixed"
                            and config["h_ms"].iloc[0] == grid.space_h_ms
                            and config["n_arc"].iloc[0] in grid.n_arcs[model])
            if space_series:
                assert config["space_error"].to_numpy() == pytest.approx(
                    error(speed, space_limit), rel=1e-6, abs=1e-8)
            else:
                assert config["space_error"].isna().all()


@pytest.mark.slow
def test_quick_summary_and_timing(quick_run):
    rows = pd.read_csv(quick_run / "work_precision.csv")
    summary = pd.read_csv(quick_run / "work_precision_summary.csv")
    refs = pd.read_csv(quick_run / "work_precision_references.csv")
    largest = rows.groupby("config")[["time_error", "space_error", "total_error"]].max()
    # exact: a configuration's maximum is one of its rows' values, and both CSVs write it with
    # the same 10 significant digits (NaN where every gait's is; none has only some NaN)
    for column in ("time", "space", "total"):
        np.testing.assert_array_equal(summary[f"max_{column}_error"].to_numpy(),
                                      largest[f"{column}_error"].to_numpy())
    presets = summary[summary["preset"].notna()].set_index("preset")
    assert sorted(presets.index) == ["accurate", "paper"]
    assert (presets["timing_batch"] == wp.QUICK_TIMING_BATCH).all()
    for name, row in presets.iterrows():
        best = min(float(t) for t in row["timing_run_times_s"].split(";"))
        # the rate is batch × duration over the best run time; the run times are written to
        # the millisecond (so within 0.5 ms of the timed ones) and the rate to 10 significant
        # digits (below 1e-10 s on the quick runs' ~0.1 s): compared as times, to 0.5 ms + 1e-9 s
        # (as a rate, 0.5 ms would be 1 % of a 50 ms run, and more on a faster machine)
        assert wp.QUICK_TIMING_BATCH * wp.QUICK_DURATION_S / row[
            "timing_robot_seconds_per_wall_s"] == pytest.approx(best, rel=0, abs=5e-4 + 1e-9)
    assert presets.loc["paper", "ratio_to_paper"] == 1.0  # its rate over itself: exact
    assert presets.loc["paper", "model"] == "undamped"
    assert presets.loc["accurate", "model"] == "damped"
    assert (presets["load_average_1min"] >= 0).all()
    assert summary["pareto"].any()
    ladders = refs[refs["ladder"] != "continuum"]
    assert (ladders["order_used"] >= wp.MIN_ORDER).all()
    assert set(zip(ladders["model"], ladders["ladder"])) == {
        (m, ladder) for m in wp.MODEL_PRESETS for ladder in ("time", "space")}


def test_pooled_order_of_a_power_law():
    h = np.array([4.0, 2.0, 1.0])
    speeds = 3.0 + np.outer(h ** 2, [2.0, -1.0])  # two gaits, second order in h
    assert wp.observed_order(*speeds) == pytest.approx(2.0)
    first_order = 3.0 + np.outer(h, [2.0, -1.0])
    assert wp.observed_order(*first_order) == pytest.approx(1.0)


def test_order_used_is_at_least_one():
    assert wp.order_used(2.3) == 2.3
    assert wp.order_used(0.4) == wp.MIN_ORDER
    assert wp.order_used(math.nan) == wp.MIN_ORDER  # no change at all between the levels


def test_pareto_front():
    run_time = [1.0, 2.0, 3.0, 4.0, 0.5]
    errors = [0.1, 0.2, 0.01, np.nan, 0.3]
    assert list(wp.pareto_front(run_time, errors)) == [True, False, True, False, True]
    # ties: the same error in a longer time is dominated (a point joins the front only with an
    # error strictly below every faster point's), whichever order the points come in
    assert list(wp.pareto_front([1.0, 2.0], [0.1, 0.1])) == [True, False]
    assert list(wp.pareto_front([2.0, 1.0], [0.1, 0.1])) == [False, True]
    # the same run time: only the lower error is on the front
    assert list(wp.pareto_front([1.0, 1.0], [0.2, 0.1])) == [False, True]
    assert list(wp.pareto_front([1.0, 1.0], [0.1, 0.2])) == [True, False]
    # a slower point one ulp better in error is on the front too
    assert list(wp.pareto_front([1.0, 2.0], [0.1, np.nextafter(0.1, 0.0)])) == [True, True]


def test_a_gaits_order_is_read_from_its_signed_changes():
    """Each gait's order came from the magnitudes of its ladder's changes, so an oscillating
    ladder (A1+A4's undamped time: 0.8646, 0.9011, 0.8470) and one whose changes flip sign got
    an order (−0.56, 3.45; an audit, 2026-12): from the signed changes they have none (NaN),
    while a monotone ladder keeps its order (changes 0.04 then 0.01: 2)."""
    speeds = np.array([[0.8646, -0.2052, 1.00], [0.9011, -0.1916, 1.04], [0.8470, -0.1929, 1.05]])
    table = wp.ladder_reference("undamped", "time", (1.0, 0.5, 0.25), speeds,
                                ["A1+A4", "A1", "A1+A2"])
    orders = table.set_index("gait")["gait_order"]
    assert np.isnan(orders["A1+A4"]) and np.isnan(orders["A1"])
    assert orders["A1+A2"] == pytest.approx(2.0, rel=1e-12)


# ----------------------------------------------------------------------------- the whole run's work

class PastTheChecks(Exception):
    """The study got past its checks to its output folder (stubbed): nothing runs."""


def past_the_checks(*args, **kwargs):
    raise PastTheChecks


def long_work_told(argv, monkeypatch):
    """The LongWorkWarnings of the study's command line up to its output folder (stubbed)."""
    monkeypatch.setattr(cli, "Output", past_the_checks)
    with warnings.catch_warnings(record=True) as caught, pytest.raises(PastTheChecks):
        warnings.simplefilter("always")
        studies_main(["work_precision", *argv])
    return [str(w.message) for w in caught if w.category is taichi_star.LongWorkWarning]


def test_the_whole_studys_hours_are_told_before_any_run(no_compute, monkeypatch):
    """--gaits all --cycles 1000: 55 configurations of 255 gaits and the presets' timing, each
    call under the warning, 5.6e10 robot-steps in all, started without a word (an audit,
    2026-12)."""
    (told,) = long_work_told(["--gaits", "all", "--cycles", "1000"], monkeypatch)
    start = ("55 configurations × 255 gait(s) and the presets' timing at 64 instances × 2 "
             "rounds, --cycles 1000 (3.15e+03 s) is ")
    # the space ladder's meshes (up to n_arc 144) and the accurate preset's weigh their nodes
    assert told.startswith(start) and " robot-steps of robots of " in told and "): about " in told
    assert float(told[len(start):].split()[0]) == pytest.approx(5.63e10, rel=1e-3)


QUICK_RUN = ("14 configurations × 2 gait(s) and the presets' timing at 8 instances × 2 rounds, "
             "--quick (0.15 s)")
QUICK_ROBOT_STEPS = 2 * (978 + 831 + 14) + 8 * (301 + 7)
"""--quick's work, counted by hand (0.15 s; adaptive steps at their fewest, dt_max 0.05 s: 3).
Undamped, 7 configurations: the preset's Euler at 1 ms (150 steps), BDF2 at 2, 1, 0.5 ms (75,
150, 300), adaptive BDF2 (3), the space ladder's n_arc 9 and 36 at 1 ms (150 each; 18 is the
time ladder's): 978. Damped, 7: the preset's adaptive BDF2 (3), BDF2 at 2, 1, 0.5 ms, adaptive
BDF2 with Newton (3), n_arc 12 and 24 at 1 ms: 831. Each for the 2 gaits after a one-step call
(14). The presets' timing, 8 instances each: a one-step call and 2 runs, 1 + 2 × 150 (paper)
and 1 + 2 × 3 (accurate)."""
QUICK_NODE_STEPS = (2 * (193 * (150 + 75 + 150 + 300 + 3 + 5) + 121 * 151 + 337 * 151
                         + 433 * (3 + 75 + 150 + 300 + 3 + 5) + 145 * 151 + 241 * 151)
                    + 8 * (193 * 301 + 433 * 7))
"""... each weighed by its robots' nodes (`timegrid.step_work`), counted by hand: the paper
preset's mesh 193 nodes, n_arc 9 121 and 36 337; the accurate preset's 433, n_arc 12 145 and
24 241 (each configuration's one-step call with it): 1,471,694 node-steps."""
QUICK_WORK = QUICK_NODE_STEPS / 193
"""--quick's work in steps of the paper robot: 7,625.4, on 241 nodes on average."""


@pytest.mark.parametrize("limit, value, refused, told", [
    ("REFUSE_ROBOT_STEPS", math.floor(QUICK_WORK), True, False),
    ("REFUSE_ROBOT_STEPS", math.ceil(QUICK_WORK), False, False),
    ("WARN_ROBOT_STEPS", math.floor(QUICK_WORK), False, True),
    ("WARN_ROBOT_STEPS", math.ceil(QUICK_WORK), False, False)])
def test_every_configurations_and_the_timings_robot_steps_are_added_up(
        no_compute, monkeypatch, tmp_path, capsys, limit, value, refused, told):
    """Refused or told past a limit just under --quick's work (its robot-steps weighed by
    their nodes), not just over it (the rule is "over"), before the output folder is made."""
    assert QUICK_NODE_STEPS == 1_471_694
    monkeypatch.setattr(timegrid, limit, value)
    argv = ["--quick", "--no-progress", "--out", str(tmp_path / "out")]
    message = (f"{QUICK_RUN} is {QUICK_ROBOT_STEPS:.3g} robot-steps of robots of 241 nodes on "
               f"average (a step 1.25 times the work of one of the paper robot's 193): about ")
    if refused:
        assert studies_main(["work_precision", *argv]) == 2
        error = capsys.readouterr().err
        assert f"error: {message}" in error and len(error.splitlines()) == 1, error
        assert not (tmp_path / "out").exists()
        return
    assert long_work_told(argv, monkeypatch) == (
        [f"{message}{QUICK_WORK / 5e4 / 3600:.3g} h at "
         f"{5e4 * QUICK_ROBOT_STEPS / QUICK_WORK:.3g} robot-steps/s (on a 2-core CPU; a GPU or "
         f"more cores run faster)"] if told else [])
