"""The gait_design study: its starts from the primitives table, its arguments checked before any
compute, and its optimiser's records against fresh simulations (objective) and a central finite
difference of one delay (gradient)."""

import numpy as np
import pandas as pd
import pytest

import taichi_star
from studies import cli, gait_design
from studies.__main__ import main as studies_main
from taichi_star import SolverConfig, StarParams
from taichi_star.output import replay


def test_arguments_fail_before_compute(no_compute, tmp_path, capsys):
    for bad in (["--cycles", "0"], ["--iterations", "0"], ["--random-starts", "-1"],
                ["--primitives", str(tmp_path / "missing.csv")]):
        assert studies_main(["gait_design", "--out", str(tmp_path / "out"), *bad]) == 2
        assert bad[0] in capsys.readouterr().err



def test_a_primitives_gait_that_names_none_and_work_of_years_fail_before_compute(
        no_compute, tmp_path, capsys):
    """A --primitives table whose gait names no gait, or one gait twice, is refused naming the
    file (a traceback inside the optimisation, after the compute: an audit, 2026-12); a study
    whose robot-steps no machine finishes is refused with its estimate, naming the counts
    (it started: the same audit)."""
    table = pd.read_csv(cli.COMMITTED_RESULTS / "primitives.csv")
    for gaits, reason in ((["A9"], "gait 'A9': unknown actuator 'A9'"),
                          (["A1+A2"] * 2, "a gait is listed twice: A1+A2,A1+A2")):
        path = tmp_path / "primitives.csv"
        table.iloc[:len(gaits)].assign(gait=gaits).to_csv(path, index=False)
        assert studies_main(["gait_design", "--quick", "--primitives", str(path), "--out",
                             str(tmp_path / "out")]) == 2
        error = capsys.readouterr().err
        assert error.startswith(f"python -m studies gait_design: error: --primitives {path}")
        assert reason in error and error.count("\n") == 1
    # more starts or sample gaits than the table ranks (cut to it without a word before)
    path = tmp_path / "three.csv"
    table.iloc[:3].to_csv(path, index=False)
    for flags in (["--synchronous-starts", "4"], ["--sample", "2", "--sample-gaits", "4"]):
        assert studies_main(["gait_design", "--quick", "--primitives", str(path), *flags,
                             "--out", str(tmp_path / "out")]) == 2
        assert capsys.readouterr().err == (
            f"python -m studies gait_design: error: {flags[-2]} must be in [1, 3] (the gaits of "
            f"--primitives {path}), got 4\n")
    # (255 + 1000) starts × 17 × 1003 evaluations + the rest, 630,000 steps each: 1.3e13
    # robot-steps, past the 9.3e12 that even the fastest machine finishes in 30 days
    assert studies_main(["gait_design", "--synchronous-starts", "255", "--random-starts",
                         "1000", "--iterations", "1000", "--cycles", "200", "--out",
                         str(tmp_path / "out")]) == 2
    error = capsys.readouterr().err
    assert ("--cycles 200 (630 s) for the study's 21,399,271 instances (each start's "
            "--iterations 1000 + 3 evaluations × 17, the sample, the synchronous gaits) at "
            "dt = 0.001 s is 1.35e+13 robot-steps") in error


def test_starts_follow_the_goal():
    primitives = pd.DataFrame({"gait": ["A1", "A2", "A3"], "step_x_mm": [1.0, 0.0, -3.0],
                               "step_y_mm": [0.0, 2.0, 0.0], "turn_deg": [0.5, -4.0, 3.0]})
    along_x = gait_design.choose_starts(primitives, "speed", 0.0, 2, 3, 3.0, seed=1)
    # projected on 0°: A1 (1) > A2 (0) > A3 (-3); the random starts cycle over the chosen sets
    assert list(along_x["gait"]) == ["A1", "A2", "A1", "A2", "A1"]
    assert list(along_x["origin"]) == ["synchronous"] * 2 + ["random 0", "random 1", "random 2"]
    random_delays = np.array(list(along_x["delays"][2:]))
    assert (random_delays >= 0).all() and (random_delays < 3.0).all()
    assert along_x["delays"][0] == (0.0,) * 8
    assert gait_design.choose_starts(primitives, "speed", 180.0, 1, 0, 3.0, 0)["gait"][0] == "A3"
    assert gait_design.choose_starts(primitives, "turn", 0.0, 1, 0, 3.0, 0)["gait"][0] == "A3"
    # clockwise: the most negative turn (A2, -4 deg) ranks first, then A1 (0.5) before A3 (3)
    clockwise = gait_design.choose_starts(primitives, "turn_cw", 0.0, 3, 0, 3.0, 0)
    assert list(clockwise["gait"]) == ["A2", "A1", "A3"]
    # the ranking the sample's --sample-gaits cuts: every gait, best first
    assert gait_design.ranked_gaits(primitives, "speed", 90.0) == ["A2", "A1", "A3"]
    assert gait_design.ranked_gaits(primitives, "turn", 0.0) == ["A3", "A1", "A2"]


@pytest.mark.slow
def test_optimiser_records_match_fresh_runs_and_finite_differences():
    base = StarParams(period=0.5)
    solver = SolverConfig(dt=5e-3)
    delays = (0.1, 0.05, 0.0, 0.0, 0.2, 0.0, 0.0, 0.0)
    starts = pd.DataFrame({"gait": ["A1+A2+A5"], "origin": ["synchronous"], "delays": [delays]})
    paths, _ = gait_design.optimise(base, solver, starts, "speed", 30.0, cycles=1,
                                    iterations=1, arch="cpu")
    first = paths.iloc[0]
    step = 0.01  # s, two steps: the delay moves the firing by whole steps, so h >= dt
    shifted = [base.replace(gait="A1+A2+A5", actuator_delays=(0.1 + sign * step,) + delays[1:])
               for sign in (0, 1, -1)]
    fresh = taichi_star.simulate(shifted, base.period, solver)
    value = gait_design.objective_of(fresh, "speed", 30.0, base.period, 1)
    # the replicas move along the tangent without touching their instance: the same run
    assert first["objective"] == pytest.approx(value[0], rel=1e-9)
    finite_difference = (value[1] - value[2]) / (2 * step)
    gradient = taichi_star.simulate(shifted[:1], base.period, solver,
                                    sensitivities=("actuator_delays[0]",))
    exact = gait_design.objective_of(
        gradient, "speed", 30.0, base.period, 1,
        read=lambda output: gradient.sensitivity(output, "actuator_delays[0]"))[0]
    assert first["gradient_norm"] >= abs(exact) * (1 - 1e-9)  # the norm bounds a component
    assert np.sign(exact) == np.sign(finite_difference) != 0
    # O(h²) truncation over a 2-step difference and the time discretisation of the delay
    assert exact == pytest.approx(finite_difference, rel=0.1)


def test_the_synchronous_table_holds_every_gait_at_offsets_zero():
    """One row per gait in the given order, each the objective of that gait fired in sync
    (fresh runs, one per gait, give the same numbers: batch-position independence is bitwise),
    so the reference is the best synchronous gait under the study's own conditions."""
    base = StarParams(period=0.5, actuator_delays=(0.1,) + (0.0,) * 7)
    solver = SolverConfig(dt=5e-3)
    gaits = ["A1+A2+A4", "A1", "A2+A3+A5"]
    table = gait_design.synchronous_objectives(base, solver, gaits, "turn", 0.0, 1, "cpu")
    assert list(table["gait"]) == gaits and (table["status"] == "ok").all()
    for gait, objective in zip(gaits, table["objective"]):
        alone = taichi_star.simulate(base.replace(gait=gait, actuator_delays=(0.0,) * 8),
                                     base.period, solver)
        assert objective == gait_design.objective_of(alone, "turn", 0.0, base.period, 1)[0]
    # A1+A2+A4 turns (about -0.15 deg in this half-second cycle) and A2+A3+A5 is the same
    # gait rotated by one actuator: the same turn to round-off (1e-9 deg); A1 is symmetric
    assert abs(table["objective"][0]) > 0.05
    assert table["objective"][0] == pytest.approx(table["objective"][2], abs=1e-9)
    assert abs(table["objective"][1]) < 1e-9
    clockwise = gait_design.synchronous_objectives(base, solver, gaits, "turn_cw", 0.0, 1, "cpu")
    # the same runs, read with the other sign: exact negation
    assert (clockwise["objective"].to_numpy() == -table["objective"].to_numpy()).all()


def test_a_turning_goal_takes_no_direction(no_compute, tmp_path, capsys):
    for goal in ("turn", "turn_cw"):
        assert studies_main(["gait_design", "--out", str(tmp_path / goal), "--goal", goal,
                             "--direction", "30"]) == 2
        assert "--direction" in capsys.readouterr().err


def test_the_sample_draws_each_spread_in_turn_and_starts_its_patterns_at_zero():
    gaits = ["A1", "A1+A3+A5", "A2+A4+A6+A8", "A1+A2+A3+A4+A5+A6+A7+A8"]
    period = 2.0
    sample = gait_design.draw_sample(gaits, 40, period, seed=3)
    assert list(sample["sample"]) == list(range(40))
    assert list(sample["spread"]) == list(gait_design.SAMPLE_SPREADS) * 8
    assert set(sample["gait"]) <= set(gaits) and sample["gait"].nunique() > 1
    for _, row in sample.iterrows():
        fired = taichi_star.Gait.parse(row["gait"]).mask.astype(bool)
        delays = row[gait_design.DELAY_COLUMNS].to_numpy(dtype=float)
        assert (delays[~fired] == 0).all()  # what the gait does not fire stays at 0
        assert delays[fired].min() == 0  # the earliest firing is at 0: the shift is exact
        # the shift keeps every offset within the spread, below the period as StarParams wants
        assert (delays < row["spread"] * period).all()
    several_fired = sample[sample["gait"] != "A1"]
    assert (several_fired[gait_design.DELAY_COLUMNS].max(axis=1) > 0).all()
    again = gait_design.draw_sample(gaits, 40, period, seed=3)
    pd.testing.assert_frame_equal(sample, again)
    other = gait_design.draw_sample(gaits, 40, period, seed=4)
    assert not other[gait_design.DELAY_COLUMNS].equals(sample[gait_design.DELAY_COLUMNS])


def test_the_sample_scores_each_pattern_as_a_run_of_its_own_and_its_best_join_the_starts():
    """Each row's objective and turn are those of a fresh run of that pattern alone (bitwise:
    batch-position independence), and the best finished rows become starts, in order."""
    base = StarParams(period=0.5)
    solver = SolverConfig(dt=5e-3)
    sample = gait_design.draw_sample(["A1+A2", "A1+A3+A4", "A2+A5"], 5, base.period, seed=0)
    scored = gait_design.sample_objectives(base, solver, sample, "speed", 45.0, 1, "cpu")
    assert (scored["status"] == "ok").all()
    for _, row in scored.iterrows():
        delays = tuple(row[gait_design.DELAY_COLUMNS].to_numpy(dtype=float))
        alone = taichi_star.simulate(base.replace(gait=row["gait"], actuator_delays=delays),
                                     base.period, solver)
        assert row["objective"] == gait_design.objective_of(alone, "speed", 45.0,
                                                            base.period, 1)[0]
        assert row["turn_deg_per_cycle"] == alone.summary["heading_deg"][0]
        assert row["newton_capped"] == alone.summary["newton_capped"][0]
    primitives = pd.DataFrame({"gait": ["A1"], "step_x_mm": [1.0], "step_y_mm": [0.0],
                               "turn_deg": [0.0]})
    # a failed pattern, however large its objective, is never a start nor a spread's best
    failed = scored.assign(status=["failed"] + ["ok"] * 4)
    failed.loc[0, "objective"] = 1e9
    assert list(gait_design.best_per_spread(failed)["sample"]) == [1, 2, 3, 4]
    # a second pattern per spread, better by 1 (its index labels repeat the first's): it wins
    # each spread but the first, where both failed
    two_per_spread = pd.concat([failed, failed.assign(sample=failed["sample"] + 5,
                                                      objective=failed["objective"] + 1)])
    assert list(gait_design.best_per_spread(two_per_spread)["sample"]) == [6, 7, 8, 9]
    starts = gait_design.choose_starts(primitives, "speed", 0.0, 1, 0, base.period, 0,
                                       failed, 2)
    order = failed.iloc[1:].sort_values("objective", ascending=False)
    assert list(starts["origin"]) == ["synchronous"] + [f"sample {k}" for k in order["sample"][:2]]
    assert starts["delays"][1] == tuple(order[gait_design.DELAY_COLUMNS].iloc[0])


def test_sample_flags_fail_before_compute(no_compute, tmp_path, capsys):
    for bad, named in ((["--sample", "-1"], "--sample"),
                       (["--sample", str(gait_design.MAX_SAMPLE + 1)], "--sample"),
                       (["--sample-starts", "1"], "--sample-starts"),  # no sample to start from
                       (["--sample", "2", "--sample-starts", "3"], "--sample-starts"),
                       (["--sample-gaits", "3"], "--sample-gaits"),  # no sample to draw
                       (["--sample", "2", "--sample-gaits", "0"], "--sample-gaits"),
                       (["--sample", "2", "--sample-gaits", "256"], "--sample-gaits")):
        assert studies_main(["gait_design", "--out", str(tmp_path / "out"), *bad]) == 2
        assert named in capsys.readouterr().err


def test_the_jet_table_is_each_patterns_own_run_projected_on_the_direction():
    """Every pattern's rows are the jet impulses of a run of it alone (bitwise: batch-position
    independence), eight spaces each, their projection on the direction the dot product, the
    objective the pattern's speed along it."""
    base = StarParams(period=0.5)
    solver = SolverConfig(dt=5e-3)
    patterns = [("designed", "A1+A2+A4", np.nan, (0.0, 0.02, 0.0, 0.01, 0.0, 0.0, 0.0, 0.0)),
                ("sample 3", "A2+A6", 0.03, (0.0,) * 8)]
    table = gait_design.jet_table(base, solver, patterns, 60.0, 1, "cpu")
    assert list(table["pattern"]) == ["designed"] * 8 + ["sample 3"] * 8
    assert list(table["space"]) == list(range(1, 9)) * 2
    for name, gait, _, delays in patterns:
        alone = taichi_star.simulate(base.replace(gait=gait, actuator_delays=delays),
                                     base.period, solver, record_interval_s=solver.dt,
                                     record_shapes=True)
        rows = table[table["pattern"] == name]
        expected = alone.jet_impulses()
        assert (rows["impulse_x_n_s_m"].to_numpy() == expected["impulse_x_n_s_m"].to_numpy()).all()
        assert (rows["impulse_y_n_s_m"].to_numpy() == expected["impulse_y_n_s_m"].to_numpy()).all()
        assert (rows["objective"] == gait_design.objective_of(alone, "speed", 60.0,
                                                              base.period, 1)[0]).all()
    along = (np.cos(np.radians(60.0)) * table["impulse_x_n_s_m"]
             + np.sin(np.radians(60.0)) * table["impulse_y_n_s_m"])
    assert (table["impulse_along_n_s_m"] == along).all()
    assert np.abs(table["impulse_along_n_s_m"]).max() > 0


def test_jets_need_fixed_euler_steps_before_compute(no_compute, tmp_path, capsys):
    assert studies_main(["gait_design", "--out", str(tmp_path / "out"), "--jets",
                         "--preset", "accurate"]) == 2
    assert "--jets" in capsys.readouterr().err


@pytest.mark.slow
def test_a_quick_run_with_a_sample_and_jets_writes_every_table(tmp_path):
    """The whole path of --sample and --jets: five sampled patterns, one per spread, each
    scored; the best one a start; the jet table holds the designed pattern, the best
    synchronous gait and each spread's best sampled pattern, eight spaces each."""
    out = tmp_path / "run"
    assert studies_main(["gait_design", "--quick", "--no-progress", "--sample", "5",
                         "--jets", "--out", str(out)]) == 0
    sample = pd.read_csv(out / "gait_design_sample.csv")
    assert list(sample["spread"]) == list(gait_design.SAMPLE_SPREADS)
    paths = pd.read_csv(out / "gait_design_paths.csv")
    best = sample.loc[sample["objective"].idxmax()]
    assert f"sample {best['sample']}" in set(paths["origin"])  # --sample-starts 1 by default
    jets = pd.read_csv(out / "gait_design_jets.csv")
    assert list(jets["pattern"].unique()) == ["designed", "synchronous",
                                              *[f"sample {k}" for k in sample["sample"]]]
    assert (jets.groupby("pattern")["space"].count() == 8).all()
    for name in ("gait_design_sample.png", "gait_design_jets.csv.json",
                 "gait_design_sample.csv.json", "gait_design_shapes.csv.json",
                 "gait_design_centroid.csv.json"):
        assert (out / name).is_file()
    # the GIF is drawn from its tables as written: replayed into a run of the same robot (the
    # designed pattern: its delays colour the heating actuators) recorded over two steps
    # alone, they redraw it byte for byte (31 frames: 30 a cycle)
    shapes = pd.read_csv(out / "gait_design_shapes.csv")
    (gait,) = shapes["gait"].unique()
    best = paths.loc[paths["objective"].idxmax()]
    assert gait == best["gait"]
    assert shapes["frame"].max() == 30
    robot = StarParams(gait=gait, actuator_delays=tuple(best[gait_design.DELAY_COLUMNS]))
    other = taichi_star.simulate([robot], 2 * gait_design.QUICK_DT,
                                 SolverConfig(dt=gait_design.QUICK_DT),
                                 record_interval_s=gait_design.QUICK_DT, record_shapes=True)
    drawn = replay(other, shapes, pd.read_csv(out / "gait_design_centroid.csv"))
    drawn.animate(tmp_path / "again.gif", title=f"designed: {gait}")
    assert (tmp_path / "again.gif").read_bytes() == (out / "gait_design.gif").read_bytes()


def earlier_run(folder, command, delays=(0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)):
    """A folder as an earlier gait_design run left it: gait_design.csv (a designed row at
    factors 1 with `delays` and one at 0.8, a synchronous row) and a sidecar recording
    `command` (no table stamp: a run of before the stamps)."""
    import json
    folder.mkdir(parents=True, exist_ok=True)
    rows = [("designed", "A1+A2+A4", 1.0, 1.0, delays), ("designed", "A1+A2+A4", 0.8, 0.8, delays),
            ("synchronous", "A1+A3", 1.0, 1.0, (0.0,) * 8)]
    table = pd.DataFrame([{"pattern": p, "gait": g, "alpha_factor": a,
                           "drag_perpendicular_factor": c, "objective": 1.0, "status": "ok",
                           **dict(zip(gait_design.DELAY_COLUMNS, d))}
                          for p, g, a, c, d in rows])
    table.to_csv(folder / "gait_design.csv", index=False)
    (folder / "gait_design.csv.json").write_text(json.dumps({"command": command}))


def test_redraw_animates_the_earlier_runs_designed_pattern_with_its_settings(tmp_path,
                                                                             monkeypatch):
    """--redraw simulates the designed row (factors 1) with the model, step and cycles of the
    recorded command (here --set alpha=0.5, --dt 5 ms, 1 cycle): its shapes table is that of a
    direct run of the pattern, and the movie heats each actuator its delay after the firing
    (the delays reach the drawing; they were ignored until 2026-12)."""
    from taichi_star import drawing
    folder = tmp_path / "earlier"
    earlier_run(folder, "python -m studies gait_design --set alpha=0.5 --dt 5e-3 --cycles 1 "
                        "--out somewhere/else")
    drawn_delays = []
    heat = drawing.periodic_hot_actuators

    def spy(times, fired, period, heating, delays=0.0):
        drawn_delays.append(tuple(delays))
        return heat(times, fired, period, heating, delays)
    monkeypatch.setattr(drawing, "periodic_hot_actuators", spy)
    assert studies_main(["gait_design", "--redraw", str(folder), "--no-progress"]) == 0
    delays = (0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0)
    assert drawn_delays == [delays]
    assert (folder / "gait_design.gif").is_file()
    shapes = pd.read_csv(folder / "gait_design_shapes.csv")
    robot = StarParams(gait="A1+A2+A4", alpha=0.5, actuator_delays=delays)
    direct = taichi_star.simulate([robot], robot.period, SolverConfig(dt=5e-3),
                                  record_interval_s=0.105, record_shapes=True)
    expected, _ = taichi_star.output.animation_tables(direct, ["A1+A2+A4"])
    # the table as written at 10 digits reads back to the recorded positions (SHAPE_DECIMALS)
    pd.testing.assert_frame_equal(shapes, expected, check_dtype=False)
    import json
    written = json.loads((folder / "gait_design_shapes.csv.json").read_text())
    assert written["details"]["redrawn_from"] == str(folder / "gait_design.csv")
    assert written["details"]["cycles"] == 1 and written["model"]["params"]["alpha"] == 0.5


@pytest.mark.parametrize("case, argv, message", [
    ("other flag", ["--cycles", "3"], "--redraw takes the earlier run's settings from its "
                                      "command: drop --cycles"),
    ("quick", ["--quick"], "drop --quick"),
    # at their default values too (compared by value, they were taken without a word, and
    # the earlier run's preset drawn: an audit, 2026-12)
    ("a default preset", ["--preset", "paper"], "command: drop --preset"),
    ("a default goal", ["--goal=speed"], "command: drop --goal"),
    ("no table", [], "gait_design.csv"),
    ("no command", [], "no recorded command"),
    ("another study", [], "is not a gait_design run"),
])
def test_redraw_refusals_are_one_line_before_compute(no_compute, tmp_path, capsys, case, argv,
                                                     message):
    folder = tmp_path / "earlier"
    if case == "no command":
        earlier_run(folder, "x")
        (folder / "gait_design.csv.json").write_text("{}")
    elif case == "another study":
        earlier_run(folder, "python -m studies primitives --dt 5e-3")
    elif case != "no table":
        earlier_run(folder, "python -m studies gait_design --dt 5e-3 --cycles 1")
    assert studies_main(["gait_design", "--redraw", str(folder), *argv]) == 2
    error = capsys.readouterr().err
    assert message in error and error.count("\n") == 1
    assert not (folder / "gait_design.gif").exists()


def test_a_turn_past_half_a_turn_is_read_unfolded_from_the_cycle_records():
    """The turning objective was the summary's heading, folded into (-180, 180], over the
    cycles: the paper model's designed turner over 9 cycles (201.2°) scored -17.6° a cycle
    instead of +22.4 (an audit, 2026-12). The records at every cycle's end unfold it: each
    cycle's turn is far below half a turn. Clockwise past -180 likewise; a robot that never
    passes ±180 keeps its summary's heading to the bit, and one without records its summary's
    heading."""
    import types

    per_cycle = 201.211 / 9
    unfolded = per_cycle * np.arange(10)                    # 0 .. 201.211 over 9 cycles
    folded = (unfolded + 180.0) % 360.0 - 180.0
    clockwise = -1.5 * unfolded                             # 0 .. -301.8
    rows = [(0, k * 3.15, h) for k, h in enumerate(folded)] + \
        [(1, k * 3.15, (h + 180.0) % 360.0 - 180.0) for k, h in enumerate(clockwise)] + \
        [(2, k * 3.15, 5.0 * k) for k in range(10)]
    result = types.SimpleNamespace(
        summary=pd.DataFrame({"heading_deg": [folded[-1], (clockwise[-1] + 180) % 360 - 180,
                                              45.0]}),
        trajectory=pd.DataFrame(rows, columns=["instance", "t_s", "heading_deg"]))
    turn = gait_design.objective_of(result, "turn", 0.0, 9 * 3.15, 9)
    np.testing.assert_allclose(turn, [per_cycle, -1.5 * per_cycle, 5.0], rtol=1e-12)
    assert turn[2] == 45.0 / 9  # unfolded by nothing: the summary's heading, to the bit
    assert gait_design.objective_of(result, "turn_cw", 0.0, 9 * 3.15, 9)[1] == -turn[1]
    bare = types.SimpleNamespace(summary=result.summary,
                                 trajectory=pd.DataFrame(columns=["instance", "t_s",
                                                                  "heading_deg"]))
    assert gait_design.objective_of(bare, "turn", 0.0, 9 * 3.15, 9)[0] == folded[-1] / 9


def test_starts_ranked_by_another_robots_primitives_are_said(no_compute, tmp_path):
    """The primitives only rank the starts, so another robot's table is not refused; but the
    no-jet run (--set alpha=0) started from the jet model's best gaits without a word (an
    audit, 2026-12): a warning names the first field that differs, before any compute. The
    table's own robot says nothing."""
    import warnings

    argv = ["--quick", "--no-progress", "--out", str(tmp_path / "run")]
    with pytest.warns(RuntimeWarning, match=r"measured on a robot whose alpha is 0.8 \(1 "
                                            r"field\(s\) differ from this run's\)"):
        with pytest.raises(AssertionError, match="simulate was called"):
            gait_design.main([*argv, "--set", "alpha=0"])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(AssertionError, match="simulate was called"):
            gait_design.main(argv)


def test_the_animation_follows_no_progress(monkeypatch):
    """The designed pattern's animation run took the library's automatic progress whatever
    --no-progress said (an audit, 2026-12): it is passed on."""
    class Stop(Exception):
        pass

    seen = {}

    def spy(*args, **kwargs):
        seen.update(kwargs)
        raise Stop
    monkeypatch.setattr(gait_design, "simulate", spy)
    for progress in (False, True):
        with pytest.raises(Stop):
            gait_design.animate_pattern(None, StarParams(), SolverConfig(), "A1", (0.0,) * 8, 1,
                                        "cpu", progress=progress)
        assert seen["progress"] is progress


def test_the_paths_are_handed_on_after_every_round(monkeypatch):
    """`optimise` hands its paths table on after every round (the study writes it then: a
    killed run kept nothing of its rounds, the table written at the end only; an audit,
    2026-12); each table holds the rounds before it, and the last is the one returned. The
    simulation replaced by a concave function of the delays (its maximum at 0.1 s)."""
    def simulate(params, *args, **kwargs):
        return np.array([p.actuator_delays for p in params])

    def objective_of(delays, goal, direction_deg, duration_s, cycles, read=None):
        return -2.0 * (delays - 0.1) if read is not None else -((delays - 0.1) ** 2).sum(axis=1)

    monkeypatch.setattr(gait_design, "simulate", simulate)
    monkeypatch.setattr(gait_design, "objective_of", objective_of)
    starts = pd.DataFrame({"gait": ["A1", "A1+A2"], "origin": ["synchronous"] * 2,
                           "delays": [(0.0,) * 8, (0.3,) * 8]})
    handed = []
    paths, _ = gait_design.optimise(StarParams(), SolverConfig(), starts, "speed", 0.0, 1,
                                    iterations=5, arch="cpu", on_round=handed.append)
    assert len(handed) == paths["evaluation"].nunique() > 1
    for number, table in enumerate(handed):
        assert table["evaluation"].max() == number
        pd.testing.assert_frame_equal(table, paths[paths["evaluation"] <= number])
