"""Gait design beyond synchronous firing: a firing offset (delay) per actuator within the
period, optimised by L-BFGS-B on the exact sensitivities, against the best synchronous gait.

    python -m studies gait_design [--goal speed|turn|turn_cw] [--direction DEG] [--cycles 2]
                                  [--synchronous-starts 3] [--random-starts 3] [--iterations 6]
                                  [--seed 0] [--primitives results/primitives.csv]
                                  [--sample 0] [--sample-starts 1] [--sample-gaits 255] [--jets]
                                  [--preset ...] [--set NAME=VALUE] [--dt S] [--out DIR] [--quick]
    python -m studies gait_design --redraw FOLDER [--out DIR]

The starts: the `--synchronous-starts` best synchronous gaits of `--primitives` for the goal
(largest step projected on `--direction`, default the direction of the fastest gait; or largest
turn per cycle, counter-clockwise for `turn`, clockwise for `turn_cw`), delays 0, and
`--random-starts` random delay patterns in [0, period) on the same actuator sets. The
objective of a start: its displacement from rest over `--cycles` cycles projected on the
direction, per simulated second (mm/s), or its heading change per cycle (deg,
counter-clockwise positive; clockwise positive for `turn_cw`: a robot whose actuators differ,
as the identified preset's gains do, turns more one way than the other).
Each start has its own L-BFGS-B search over its 8 delays, bounded to [0, period), with its
own line search (`studies.optimise.minimise_lbfgsb_batched`; until 2026-12 one search maximised
the starts' sum, whose shared line search tied their step lengths). The searches' evaluations
are batched: one `simulate(..., sensitivities=("actuator_delays",))` call per round gives every
running start's objective and its gradient in the 8 delays; a search that has stopped drops
out of the later rounds.

`--sample N` first simulates N random patterns in one batch (no gradients), a picture of the
whole landscape that a few local searches cannot give: pattern k fires a gait drawn uniformly
from the primitives table (from its `--sample-gaits` best for the goal), its actuators'
offsets uniform within SAMPLE_SPREADS[k mod 5] of the period (1 % to all of it), shifted so
that the first fires at 0. The best `--sample-starts` of
them join the starts (origin "sample k").

Writes into --out (default runs/gait_design/<timestamp>/), each CSV with its provenance sidecar:
- `gait_design_paths.csv`: every evaluation of every start (evaluation, start, gait, origin,
  objective, gradient norm, the 8 delays in s);
- `gait_design_synchronous.csv`: every synchronous gait of `--primitives` (offsets 0) under
  the same conditions (cycles from rest, solver), one batch: gait, objective, status;
- `gait_design.csv`: the best pattern ("designed") and the best synchronous gait of that table
  ("synchronous"), each simulated over the same cycles with the same solver, at α and
  drag_perpendicular × 0.8, 1 and 1.2 (the centre and 4 corners; one batch): objective per case;
- `gait_design.png` (objective per evaluation per start, and the robustness), drawn from the
  CSVs;
- `gait_design_shapes.csv` (gait, frame, t_s, node, x_mm, y_mm: every node of the best
  pattern's robot at 30 records a cycle over its cycles) and `gait_design_centroid.csv`
  (gait, frame, t_s, x_mm, y_mm: its centroid relative to its start), the tables of
  `taichi_star.output.animation_tables`, and `gait_design.gif`, the best pattern's animation,
  drawn from them as written (read back and replayed into the run, `taichi_star.output.replay`);
- with `--sample`: `gait_design_sample.csv` (sample, gait, spread, objective, its turn per
  cycle, status, newton_capped, the 8 delays in s) and `gait_design_sample.png` (objective against spread,
  the best synchronous gait's as a line), drawn from it and the synchronous table;
- with `--jets`: `gait_design_jets.csv`, where the thrust comes from: the designed pattern's,
  the best synchronous gait's and (with `--sample`) each spread's best sampled pattern's jet
  impulse per inter-limb space (`SimulationResult.jet_impulses`, one batch recorded at every
  step; implicit Euler with fixed steps only), also projected on the direction.

`--redraw FOLDER` optimises nothing: it simulates an earlier run's designed pattern again (the
"designed" row of FOLDER/gait_design.csv at α and C⊥ × 1, with the model, solver and cycles of
the command its sidecar records, parsed by today's flags) and writes its animation tables and
`gait_design.gif` into --out (default FOLDER itself), for a run drawn before a change to the
drawing (until 2026-12 the animation drew every actuator heating at the cycle's start, its
delay ignored).
"""

from __future__ import annotations

import shlex
import sys
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from taichi_star import Gait, simulate
from taichi_star.diagnostics import check_jet_solver
from taichi_star.metrics import wrap_degrees
from taichi_star.output import animation_tables, read_provenance, replay
from taichi_star.sensitivities import instances_per_instance
from taichi_star.timegrid import nearest_interval

from . import cli
from .optimise import minimise_lbfgsb_batched

DESCRIPTION = ("Firing offsets per actuator optimised by L-BFGS-B on the exact sensitivities "
               "for speed in a direction or turning, against the best synchronous gait.")
DEFAULT_PRIMITIVES = cli.COMMITTED_RESULTS / "primitives.csv"
PRIMITIVE_NUMBERS = ["step_mm", "direction_deg", "step_x_mm", "step_y_mm", "turn_deg"]
"""The columns of the --primitives table this study reads besides gait: numbers, NaN where the
table has none (a failed gait's steps, the direction of a step too short to have one)."""
ROBUSTNESS_SCALES = ((1.0, 1.0), (0.8, 0.8), (0.8, 1.2), (1.2, 0.8), (1.2, 1.2))
"""(α factor, drag_perpendicular factor): the centre, then the 4 corners of ±20 %."""
DELAY_MARGIN = 1e-6
"""The delays' upper bound is period·(1 − DELAY_MARGIN): StarParams wants them < period."""
QUICK_DT = 5e-3
QUICK_CYCLES = 1
TURN_SIGNS = {"turn": 1.0, "turn_cw": -1.0}
"""The turning goals: the sign that makes their turn per cycle positive (heading_deg is
counter-clockwise positive)."""
GOALS = ("speed", *TURN_SIGNS)
DELAY_COLUMNS = [f"delay{k + 1}_s" for k in range(8)]
"""The tables' columns of the 8 actuators' offsets (s)."""
MAX_SYNCHRONOUS_STARTS = 255
"""The most synchronous starts (--synchronous-starts): every non-empty gait, the most rows a
primitives table has."""
MAX_RANDOM_STARTS = 1000
"""The most random starts (--random-starts), each an instance of every evaluation's batch (the
committed runs: 0 and 2)."""
MAX_ITERATIONS = 1000
"""The most L-BFGS-B iterations (--iterations; the committed runs: 3 and 10); each takes one
or more evaluations (its line search), a batch of the searches' points simulated with their
sensitivities, and a search stops after --iterations + 3 evaluations at most (until
2026-12-06 scipy finished a line search past that: the committed runs count what they made)."""
SAMPLE_SPREADS = (0.01, 0.03, 0.1, 0.3, 1.0)
"""Shares of the period within which a sampled pattern's offsets are drawn (--sample), in
turn: from a few time steps off synchronous firing, where the local searches look, to
anywhere in the period."""
MAX_SAMPLE = 100_000
"""The most sampled patterns (--sample), one batch without gradients: about an hour on 2
cores at h = 5 ms over 2 cycles."""


def objective_of(result, goal: str, direction_deg: float, duration_s: float, cycles: int,
                 read=None):
    """The objective per instance (B,): the displacement projected on direction_deg per second
    (mm/s), or the heading change per cycle (deg). `read(output)` gives an output's values
    (default: the summary column); with `read = lambda output: result.sensitivity(output,
    "actuator_delays")` the same linear map gives the gradient in the 8 delays (B, 8)."""
    if goal in TURN_SIGNS:
        # the summary's heading is folded into (-180, 180]: past half a turn it read a turn of
        # 201° as -159° (an audit, 2026-12); the derivative is that of the unfolded heading
        turned = (read("heading_deg") if read is not None
                  else result.summary["heading_deg"].to_numpy() + 360.0 * whole_turns(result))
        return TURN_SIGNS[goal] * turned / cycles
    read = read or (lambda output: result.summary[output].to_numpy())
    cosine, sine = np.cos(np.radians(direction_deg)), np.sin(np.radians(direction_deg))
    return (cosine * read("displacement_x_mm") + sine * read("displacement_y_mm")) / duration_s


def whole_turns(result) -> np.ndarray:
    """(B,) whole turns to add to each instance's summary heading (folded into (-180, 180])
    to get the heading it reached, from its records (at least one per cycle: each cycle's
    turn, far below half a turn, is read unfolded); 0 for an instance without records."""
    turns = np.zeros(len(result.summary))
    final = result.summary["heading_deg"].to_numpy()
    for instance, part in result.trajectory.groupby("instance"):
        heading = part.sort_values("t_s")["heading_deg"].to_numpy()
        steps = wrap_degrees(np.diff(heading))
        turns[instance] = np.round((heading[0] + steps.sum() - final[instance]) / 360.0)
    return turns


def ranked_gaits(primitives: pd.DataFrame, goal: str, direction_deg: float) -> list:
    """The primitives table's gaits, best first for the goal: by step projected on
    direction_deg, or by turn per cycle in the goal's sense (ties in the table's order)."""
    if goal in TURN_SIGNS:
        score = TURN_SIGNS[goal] * primitives["turn_deg"]
    else:
        score = (primitives["step_x_mm"] * np.cos(np.radians(direction_deg))
                 + primitives["step_y_mm"] * np.sin(np.radians(direction_deg)))
    return list(primitives.assign(score=score).sort_values("score", ascending=False,
                                                           kind="stable")["gait"])


def choose_starts(primitives: pd.DataFrame, goal: str, direction_deg: float, n_synchronous: int,
                  n_random: int, period: float, seed: int,
                  sample: pd.DataFrame = None, n_sample: int = 0) -> pd.DataFrame:
    """The starts: gait, origin ("synchronous", "random k" or "sample k"), delays (tuple of 8,
    s); the last are the `n_sample` best finished rows of `sample` (`sample_objectives`)."""
    best = ranked_gaits(primitives, goal, direction_deg)[:n_synchronous]
    rows = [(gait, "synchronous", (0.0,) * 8) for gait in best]
    rng = np.random.default_rng(seed)
    for k in range(n_random):
        gait = best[k % len(best)]
        rows.append((gait, f"random {k}", tuple(rng.uniform(0, period * (1 - DELAY_MARGIN), 8))))
    if n_sample:
        finished = sample[sample["status"] == "ok"]
        for _, row in finished.nlargest(n_sample, "objective", keep="first").iterrows():
            rows.append((row["gait"], f"sample {int(row['sample'])}",
                         tuple(float(row[column]) for column in DELAY_COLUMNS)))
    return pd.DataFrame(rows, columns=["gait", "origin", "delays"])


def draw_sample(gaits: Sequence[str], n: int, period: float, seed: int) -> pd.DataFrame:
    """`n` random firing patterns (sample, gait, spread, the 8 delays in s): pattern k fires a
    gait drawn uniformly from `gaits`, each of its actuators at an offset uniform in
    [0, spread·period), spread = SAMPLE_SPREADS[k mod 5], the offsets then shifted so that the
    earliest is 0 (a pattern that starts late only loses time against one that starts at 0);
    actuators the gait does not fire keep offset 0."""
    rng = np.random.default_rng([seed, 1])  # a stream apart from the random starts' (seed)
    rows = []
    for k in range(n):
        gait = gaits[rng.integers(len(gaits))]
        spread = SAMPLE_SPREADS[k % len(SAMPLE_SPREADS)]
        fired = Gait.parse(gait).mask.astype(bool)
        offsets = np.where(fired, rng.uniform(0.0, spread * period * (1 - DELAY_MARGIN), 8), 0.0)
        offsets[fired] -= offsets[fired].min()
        rows.append({"sample": k, "gait": gait, "spread": spread,
                     **dict(zip(DELAY_COLUMNS, offsets))})
    return pd.DataFrame(rows, columns=["sample", "gait", "spread", *DELAY_COLUMNS])


def best_per_spread(sample: pd.DataFrame) -> pd.DataFrame:
    """The best finished pattern of each spread of a scored sample (`sample_objectives`), in
    increasing spread."""
    finished = sample[sample["status"] == "ok"]
    # by position, not by index label: a table put together from pieces may repeat labels
    best_first = finished.sort_values("objective", ascending=False, kind="stable")
    return best_first.groupby("spread").head(1).sort_values("spread", kind="stable")


def sample_objectives(base, solver, sample: pd.DataFrame, goal, direction_deg, cycles,
                      arch, progress: bool = True) -> pd.DataFrame:
    """`sample` (`draw_sample`) with each pattern's objective, its turn per cycle
    (turn_deg_per_cycle, counter-clockwise positive: what a speed lost to asynchronous firing
    went into), status and newton_capped (an 'ok' run with a Newton solve that used all its
    iterations, to be checked at a smaller dt), from one batch under the study's conditions."""
    duration_s = cycles * base.period
    params = [base.replace(gait=gait, actuator_delays=tuple(delays))
              for gait, delays in zip(sample["gait"], sample[DELAY_COLUMNS].to_numpy())]
    # a record at every cycle's end: the headings unfolded past half a turn (`whole_turns`)
    result = simulate(params, duration_s, solver, arch=arch, progress=progress,
                      record_interval_s=base.period)
    return sample.assign(
        objective=objective_of(result, goal, direction_deg, duration_s, cycles),
        turn_deg_per_cycle=objective_of(result, "turn", direction_deg, duration_s, cycles),
        status=result.summary["status"].to_numpy(),
        newton_capped=result.summary["newton_capped"].to_numpy())[
            ["sample", "gait", "spread", "objective", "turn_deg_per_cycle", "status",
             "newton_capped", *DELAY_COLUMNS]]


def optimise(base, solver, starts, goal, direction_deg, cycles, iterations, arch,
             on_round=None):
    """One L-BFGS-B search per start over its 8 delays, each with its own line search, their
    evaluations batched (`optimise.minimise_lbfgsb_batched`: one simulation with the delay
    sensitivities per round, holding every search still running); returns (paths table, best
    row per start). `on_round(paths)`, if given, gets the paths table after every round (the
    study writes it: a killed run keeps the rounds it made)."""
    period = base.period
    duration_s = cycles * period
    gaits = list(starts["gait"])
    upper = period * (1 - DELAY_MARGIN)
    path_rows = []

    def evaluate(indices, points):
        delays = np.clip(points, 0.0, upper)
        params = [base.replace(gait=gaits[start], actuator_delays=tuple(row))
                  for start, row in zip(indices, delays)]
        result = simulate(params, duration_s, solver, arch=arch, record_interval_s=period,
                          sensitivities=("actuator_delays",), progress=False)
        value = objective_of(result, goal, direction_deg, duration_s, cycles)
        gradient = objective_of(result, goal, direction_deg, duration_s, cycles,
                                read=lambda output: result.sensitivity(output, "actuator_delays"))
        evaluation = path_rows[-1]["evaluation"] + 1 if path_rows else 0
        for position, (start, row) in enumerate(zip(indices, delays)):
            path_rows.append({"evaluation": evaluation, "start": start, "gait": gaits[start],
                              "origin": starts["origin"].iloc[start],
                              "objective": value[position],
                              "gradient_norm": float(np.linalg.norm(gradient[position])),
                              **dict(zip(DELAY_COLUMNS, row))})
        if on_round is not None:
            on_round(pd.DataFrame(path_rows))
        return -value, -gradient  # the searches minimise

    initial = [np.array(d, dtype=float) for d in starts["delays"]]
    minimise_lbfgsb_batched(evaluate, initial, [(0.0, upper)] * 8, max_iterations=iterations,
                            max_evaluations=iterations + 3)
    paths = pd.DataFrame(path_rows)
    best = paths.loc[paths.groupby("start")["objective"].idxmax()].sort_values("start")
    return paths, best


def robustness(base, solver, patterns, goal, direction_deg, cycles, arch) -> pd.DataFrame:
    """Each (name, gait, delays) of `patterns` at every ROBUSTNESS_SCALES case, one batch."""
    duration_s = cycles * base.period
    cases = [(name, gait, delays, a, c) for name, gait, delays in patterns
             for a, c in ROBUSTNESS_SCALES]
    params = [base.replace(gait=gait, actuator_delays=tuple(delays), alpha=base.alpha * a,
                           drag_perpendicular=base.drag_perpendicular * c)
              for _, gait, delays, a, c in cases]
    result = simulate(params, duration_s, solver, arch=arch, progress=False,
                      record_interval_s=base.period)
    value = objective_of(result, goal, direction_deg, duration_s, cycles)
    return pd.DataFrame([{"pattern": name, "gait": gait, "alpha_factor": a,
                          "drag_perpendicular_factor": c, "objective": v,
                          "status": status, **dict(zip(DELAY_COLUMNS, delays))}
                         for (name, gait, delays, a, c), v, status
                         in zip(cases, value, result.summary["status"])])


def synchronous_objectives(base, solver, gaits, goal, direction_deg, cycles,
                           arch) -> pd.DataFrame:
    """Every synchronous gait of `gaits` (all offsets 0) under the study's conditions (cycles
    from rest, solver), one batch: gait, objective, status; the reference the designed pattern
    is judged against is the best of them."""
    duration_s = cycles * base.period
    params = [base.replace(gait=gait, actuator_delays=(0.0,) * 8) for gait in gaits]
    result = simulate(params, duration_s, solver, arch=arch, progress=False,
                      record_interval_s=base.period)
    return pd.DataFrame({"gait": list(gaits),
                         "objective": objective_of(result, goal, direction_deg, duration_s,
                                                   cycles),
                         "status": result.summary["status"].to_numpy()})


def jet_table(base, solver, patterns, direction_deg, cycles, arch) -> pd.DataFrame:
    """Each (name, gait, spread, delays) of `patterns` run once over the study's cycles with a
    record at every step; one row per pattern and inter-limb space: pattern, gait, spread,
    objective (speed along direction_deg, mm/s), space, impulse_x_n_s_m, impulse_y_n_s_m,
    impulse_along_n_s_m (on direction_deg), jetting_s (`SimulationResult.jet_impulses`)."""
    duration_s = cycles * base.period
    params = [base.replace(gait=gait, actuator_delays=tuple(delays))
              for _, gait, _, delays in patterns]
    result = simulate(params, duration_s, solver, arch=arch, record_interval_s=solver.dt,
                      record_shapes=True, progress=False)
    speed = objective_of(result, "speed", direction_deg, duration_s, cycles)
    impulses = result.jet_impulses()
    cosine, sine = np.cos(np.radians(direction_deg)), np.sin(np.radians(direction_deg))
    names = pd.DataFrame([{"instance": k, "pattern": name, "gait": gait, "spread": spread,
                           "objective": speed[k]}
                          for k, (name, gait, spread, _) in enumerate(patterns)])
    table = names.merge(impulses, on="instance").drop(columns="instance")
    table["impulse_along_n_s_m"] = (cosine * table["impulse_x_n_s_m"]
                                    + sine * table["impulse_y_n_s_m"])
    return table


def plot_design(paths_csv, table_csv, png_path, unit: str) -> Path:
    """Left: every start's objective per evaluation; right: best pattern vs best synchronous
    gait at the robustness cases."""
    plt = cli.use_agg()
    paths, table = pd.read_csv(paths_csv), pd.read_csv(table_csv)
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for start, path in paths.groupby("start"):
        left.plot(path["evaluation"], path["objective"], marker=".",
                  label=f"{path['gait'].iloc[0]} ({path['origin'].iloc[0]})")
    left.set(xlabel="evaluation (one batch)", ylabel=f"objective ({unit})",
             title="L-BFGS-B paths")
    left.legend(fontsize=6)
    labels = [f"α×{a:g}\nC⊥×{c:g}" for a, c in ROBUSTNESS_SCALES]
    width = 0.4
    for offset, (name, group) in zip((-width / 2, width / 2), table.groupby("pattern", sort=False)):
        right.bar(np.arange(len(group)) + offset, group["objective"], width, label=name)
    right.set_xticks(np.arange(len(labels)), labels, fontsize=7)
    right.set(ylabel=f"objective ({unit})", title="robustness (±20 % in α and C⊥)")
    right.legend(fontsize=7)
    return cli.save_figure(fig, png_path, dpi=120)


def plot_sample(sample_csv, synchronous_csv, png_path, unit: str) -> Path:
    """Every sampled pattern's objective against its spread (log axis, each spread's points
    jittered), the best synchronous gait's objective as a line."""
    plt = cli.use_agg()
    sample, synchronous = pd.read_csv(sample_csv), pd.read_csv(synchronous_csv)
    fig, axes = plt.subplots(figsize=(6, 4))
    finished = sample[sample["status"] == "ok"]
    jitter = np.random.default_rng(0).uniform(0.85, 1.15, len(finished))
    axes.scatter(finished["spread"] * jitter, finished["objective"], s=3, alpha=0.3,
                 label=f"random patterns ({len(finished)})")
    best = synchronous.loc[synchronous[synchronous["status"] == "ok"]["objective"].idxmax()]
    axes.axhline(best["objective"], color="k", linestyle="--",
                 label=f"best synchronous ({best['gait']})")
    axes.set_xscale("log")
    axes.set(xlabel="offsets drawn within this share of the period",
             ylabel=f"objective ({unit})", title="random firing patterns")
    axes.legend(fontsize=7, loc="lower left")  # the best patterns lie near the top
    return cli.save_figure(fig, png_path, dpi=120)


def build_parser():
    parser = cli.StudyParser("gait_design", DESCRIPTION)
    cli.add_model_flags(parser, fixed=("gait", "actuator_delays"))
    cli.add_dt_flag(parser, quick=QUICK_DT)
    parser.add_argument("--goal", choices=GOALS, default="speed",
                        help="maximise speed along --direction, or turning per cycle: "
                             "counter-clockwise (turn) or clockwise (turn_cw)")
    parser.add_argument("--direction", type=float, default=None,
                        help="direction of travel, deg (none: the fastest synchronous gait's)")
    parser.add_argument("--cycles", type=int, default=2, quick=QUICK_CYCLES,
                        help="actuation cycles from rest per evaluation")
    parser.add_argument("--synchronous-starts", type=int, default=3, quick=1,
                        help=f"best synchronous gaits started from, at most "
                             f"{MAX_SYNCHRONOUS_STARTS}")
    parser.add_argument("--random-starts", type=int, default=3, quick=1,
                        help=f"random delay patterns on those gaits' actuator sets, at most "
                             f"{MAX_RANDOM_STARTS}")
    parser.add_argument("--iterations", type=int, default=6, quick=1,
                        help=f"L-BFGS-B iterations at most, in [1, {MAX_ITERATIONS}]")
    parser.add_argument("--seed", type=int, default=0, help="seed of the random starts")
    parser.add_argument("--primitives", default=str(DEFAULT_PRIMITIVES),
                        help="the synchronous gaits' primitives CSV (default a checkout's "
                             "results/primitives.csv)")
    parser.add_argument("--sample", type=int, default=0,
                        help=f"random patterns simulated first, one batch, at most {MAX_SAMPLE}")
    parser.add_argument("--sample-starts", type=int, default=None,
                        help="the sample's best patterns that join the starts, at most --sample "
                             "(default 1 with a sample)")
    parser.add_argument("--sample-gaits", type=int, default=None,
                        help="the sample draws from this many of the best synchronous gaits for "
                             "the goal (default: every gait of --primitives)")
    parser.add_argument("--jets", action="store_true",
                        help="each inter-limb space's jet impulse for the designed, the best "
                             "synchronous and each spread's best sampled pattern "
                             "(gait_design_jets.csv; implicit Euler with fixed steps)")
    parser.add_argument("--redraw", default=None, metavar="FOLDER",
                        help="optimise nothing: draw an earlier run's designed pattern again "
                             "(FOLDER/gait_design.csv and the command its sidecar records) into "
                             "--out (default FOLDER)")
    return parser


REDRAW_FLAGS = ("redraw", "out", "arch", "no_progress")
"""The flags `--redraw` takes (every other setting comes from the earlier run's command)."""


def animate_pattern(out, base, solver, gait: str, delays, cycles: int, arch, progress: bool):
    """Simulate the pattern (`gait` firing with `delays` (8,) s) over `cycles` from rest,
    recorded 30 times a cycle (a progress bar with `progress`), and write its animation tables
    (gait_design_shapes.csv, gait_design_centroid.csv) and gait_design.gif drawn from them as
    written."""
    shown = simulate(base.replace(gait=gait, actuator_delays=tuple(delays)),
                     cycles * base.period, solver, arch=arch,
                     record_interval_s=nearest_interval(base.period / 30, solver.dt),
                     record_shapes=True, progress=progress)
    shapes, centroid = animation_tables(shown, [gait])
    shapes_csv = out.write_csv(shapes, "gait_design_shapes.csv")
    centroid_csv = out.write_csv(centroid, "gait_design_centroid.csv")
    drawn = replay(shown, pd.read_csv(shapes_csv), pd.read_csv(centroid_csv))
    out.wrote(drawn.animate(out.path("gait_design.gif"), title=f"designed: {gait}"))


def redraw(args, argv):
    """--redraw: the designed pattern of an earlier run drawn again (`animate_pattern`) with
    the model, solver and cycles of its recorded command, its delays as gait_design.csv keeps
    them (10 significant digits: the run's objective again to about that many);
    StudyArgumentError naming --redraw
    for a folder without a readable gait_design.csv and sidecar, and naming any other flag
    given beside it (the run's own settings would silently replace it)."""
    parser = build_parser()
    # --quick changes other flags' defaults: named alone; a flag given at its default value
    # is named too (it was compared by value, so `--preset paper` beside a run of the
    # identified preset drew that run without a word; an audit, 2026-12)
    alone = vars(parser.parse_args(["--redraw", args.redraw]))
    words = list(argv) if argv is not None else sys.argv[1:]
    written = {word[2:].split("=", 1)[0].replace("-", "_") for word in words
               if word.startswith("--")}
    given = ["--quick"] if args.quick else [
        f"--{name.replace('_', '-')}" for name, value in vars(args).items()
        if name not in REDRAW_FLAGS and (value != alone[name] or name in written)]
    if given:
        raise cli.StudyArgumentError(f"--redraw takes the earlier run's settings from its "
                                     f"command: drop {', '.join(given)}")
    table_path = Path(args.redraw) / "gait_design.csv"
    table = cli.read_table(table_path, "--redraw", ["pattern", "gait", "alpha_factor",
                                                    "drag_perpendicular_factor", *DELAY_COLUMNS],
                           "a gait_design.csv")
    try:
        command = read_provenance(table_path)["command"]
    except (OSError, ValueError, KeyError, TypeError) as error:
        raise cli.StudyArgumentError(f"--redraw {table_path}: no recorded command to take the "
                                     f"run's settings from ({error})") from None
    words = shlex.split(command)
    if "gait_design" not in words:
        raise cli.StudyArgumentError(f"--redraw {table_path}: its command is not a gait_design "
                                     f"run: {command}")
    run = cli.parse(parser, words[words.index("gait_design") + 1:])
    centre = table[(table["pattern"] == "designed") & (table["alpha_factor"] == 1)
                   & (table["drag_perpendicular_factor"] == 1)]
    if len(centre) != 1:
        raise cli.StudyArgumentError(f"--redraw {table_path}: no single designed row at "
                                     f"alpha and drag_perpendicular factors 1")
    designed = centre.iloc[0]
    base, solver = cli.base_params(run), cli.solver(run)
    if args.out is None:
        args.out = args.redraw
    out = cli.Output(args, argv or [], model={"preset": run.preset, "params": base},
                     solver=solver, extra={"redrawn_from": str(table_path),
                                           "command_of_run": command, "cycles": run.cycles})
    animate_pattern(out, base, solver, str(designed["gait"]),
                    designed[DELAY_COLUMNS].to_numpy(dtype=float), run.cycles, args.arch,
                    progress=not args.no_progress)
    out.report()


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    if args.redraw is not None:
        redraw(args, argv)
        return
    if args.cycles < 1:
        raise cli.StudyArgumentError(f"--cycles must be >= 1, got {args.cycles}")
    if args.seed < 0:
        raise cli.StudyArgumentError(f"--seed must be >= 0, got {args.seed}")
    for flag, lowest, highest in (("synchronous_starts", 1, MAX_SYNCHRONOUS_STARTS),
                                  ("random_starts", 0, MAX_RANDOM_STARTS),
                                  ("iterations", 1, MAX_ITERATIONS),
                                  ("sample", 0, MAX_SAMPLE)):
        cli.check_count(getattr(args, flag), f"--{flag.replace('_', '-')}", lowest, highest)
    if args.sample_starts is None:
        args.sample_starts = min(args.sample, 1)
    cli.check_count(args.sample_starts, "--sample-starts", 0, args.sample)
    if args.sample_gaits is not None:
        cli.check_count(args.sample_gaits, "--sample-gaits", 1, MAX_SYNCHRONOUS_STARTS)
        if not args.sample:
            raise cli.StudyArgumentError("--sample-gaits: only with --sample N (N >= 1)")
    if args.direction is not None and not -360 <= args.direction <= 360:
        raise cli.StudyArgumentError(f"--direction must be an angle in [-360, 360] deg, got "
                                     f"{args.direction}")
    if args.direction is not None and args.goal in TURN_SIGNS:
        raise cli.StudyArgumentError("--direction: only with --goal speed (turning has no "
                                     "direction)")
    # its period, step and robot are not refused as plan refuses them: the table only ranks
    # the gaits to start from, and every gait is simulated again here (the default,
    # results/primitives.csv at 1 ms, serves --quick's 5 ms as well); another robot is said,
    # since it ranks the starts by its own steps (the no-jet run started from the jet
    # model's best gaits without a word; an audit, 2026-12)
    primitives = cli.read_table(cli.committed_input(args.primitives, "--primitives",
                                                    "primitives"),
                                "--primitives", ["gait", *PRIMITIVE_NUMBERS], "a primitives table")
    cli.numeric_columns(primitives, PRIMITIVE_NUMBERS, args.primitives, "--primitives")
    # its gaits are fired by name: one that names no gait, or twice, is refused here (it failed
    # with a traceback inside the optimisation, after the compute: an audit, 2026-12)
    cli.resolve_gaits(",".join(map(str, primitives["gait"])), f"--primitives {args.primitives}")
    usable = primitives[np.isfinite(primitives[PRIMITIVE_NUMBERS]).all(axis=1)]
    if usable.empty:
        # the default direction is the fastest such gait's; NaN alone ranks no gait
        raise cli.StudyArgumentError(f"--primitives {args.primitives}: no gait whose "
                                     f"{', '.join(PRIMITIVE_NUMBERS[:-1])} and "
                                     f"{PRIMITIVE_NUMBERS[-1]} are all finite")
    # more starts or sample gaits than the table ranks were cut to it without a word (an
    # audit, 2026-12)
    for flag, value in (("--synchronous-starts", args.synchronous_starts),
                        ("--sample-gaits", args.sample_gaits)):
        if value is not None and value > len(primitives):
            raise cli.StudyArgumentError(f"{flag} must be in [1, {len(primitives)}] (the gaits "
                                         f"of --primitives {args.primitives}), got {value}")
    base = cli.base_params(args)
    recorded, differing = cli.robot_differences(args.primitives, base)
    if differing:
        warnings.warn(f"--primitives {args.primitives}: measured on a robot whose "
                      f"{differing[0]} is {recorded[differing[0]]} ({len(differing)} field(s) "
                      f"differ from this run's): its gaits rank the starts by that robot's "
                      f"steps", RuntimeWarning, stacklevel=2)
    solver = cli.solver(args)
    if args.jets:
        try:
            check_jet_solver(solver)
        except ValueError as error:
            raise cli.StudyArgumentError(f"--jets: {error}") from None
    # every evaluation runs --cycles from rest, even under --quick
    cli.check_cycles({"--cycles": args.cycles}, base.period, solver)
    # the whole study's instances, at most: each start's evaluations (the pattern and its
    # delays' replica pairs), the sample, the synchronous gaits, the designed and the best
    # synchronous pattern in every robustness case, the animation; their robot-steps refused
    # or estimated before any compute (a run of years started without a word: an audit,
    # 2026-12)
    per_evaluation = instances_per_instance(len(DELAY_COLUMNS))
    starts = args.synchronous_starts + args.random_starts + (args.sample_starts or 0)
    instances = (starts * per_evaluation * (args.iterations + 3) + (args.sample or 0)
                 + len(primitives) + 2 * len(ROBUSTNESS_SCALES) + 1)
    cli.check_run(f"--cycles {args.cycles} ({args.cycles * base.period:.3g} s) for the study's "
                  f"{instances:,} instances (each start's --iterations {args.iterations} + 3 "
                  f"evaluations × {per_evaluation}, the sample, the synchronous gaits)",
                  args.cycles * base.period, solver, batch=instances, arch=cli.work_arch(args),
                  nodes=base.n_nodes)
    fastest = usable.loc[usable["step_mm"].idxmax()]
    direction = float(fastest["direction_deg"]) if args.direction is None else args.direction
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"goal": args.goal, "direction_deg": direction,
                                           "cycles": args.cycles})
    unit = (f"deg per cycle ({'clockwise' if TURN_SIGNS[args.goal] < 0 else 'counter-clockwise'})"
            if args.goal in TURN_SIGNS else "mm/s along the direction")
    sample = None
    if args.sample:
        sample = sample_objectives(base, solver,
                                   draw_sample(ranked_gaits(primitives, args.goal,
                                                            direction)[:args.sample_gaits],
                                               args.sample, base.period, args.seed),
                                   args.goal, direction, args.cycles, args.arch,
                                   progress=not args.no_progress)
        sample_csv = out.write_csv(sample, "gait_design_sample.csv")
    starts = choose_starts(primitives, args.goal, direction, args.synchronous_starts,
                           args.random_starts, base.period, args.seed, sample,
                           args.sample_starts)
    # written after every round, whole (its sidecar with it): a killed run keeps the rounds it
    # made (they were written at the end only: an audit, 2026-12)
    paths, best = optimise(base, solver, starts, args.goal, direction, args.cycles,
                           args.iterations, args.arch,
                           on_round=lambda paths: out.write_csv(paths, "gait_design_paths.csv"))
    paths_csv = out.write_csv(paths, "gait_design_paths.csv")
    winner = best.loc[best["objective"].idxmax()]
    synchronous = synchronous_objectives(base, solver, list(primitives["gait"]), args.goal,
                                         direction, args.cycles, args.arch)
    synchronous_csv = out.write_csv(synchronous, "gait_design_synchronous.csv")
    if args.sample:
        out.wrote(plot_sample(sample_csv, synchronous_csv, out.path("gait_design_sample.png"),
                              unit))
    finished = synchronous[synchronous["status"] == "ok"]
    reference = finished.loc[finished["objective"].idxmax()]
    patterns = [("designed", winner["gait"], tuple(winner[DELAY_COLUMNS])),
                ("synchronous", reference["gait"], (0.0,) * 8)]
    table = robustness(base, solver, patterns, args.goal, direction, args.cycles, args.arch)
    table_csv = out.write_csv(table, "gait_design.csv")
    if args.jets:
        jet_patterns = [(name, gait, np.nan, delays) for name, gait, delays in patterns]
        if args.sample:
            jet_patterns += [(f"sample {int(row['sample'])}", row["gait"], row["spread"],
                              tuple(row[DELAY_COLUMNS]))
                             for _, row in best_per_spread(sample).iterrows()]
        out.write_csv(jet_table(base, solver, jet_patterns, direction, args.cycles, args.arch),
                      "gait_design_jets.csv")
    out.wrote(plot_design(paths_csv, table_csv, out.path("gait_design.png"), unit))
    animate_pattern(out, base, solver, winner["gait"], patterns[0][2], args.cycles, args.arch,
                    progress=not args.no_progress)
    out.report()
    centre = table[(table["alpha_factor"] == 1) & (table["drag_perpendicular_factor"] == 1)]
    designed, plain = centre["objective"].to_numpy()
    print(f"direction {direction:g} deg, {unit}: best designed {designed:.4g} "
          f"({winner['gait']}), best synchronous {plain:.4g} ({reference['gait']}), "
          f"ratio {designed / plain:.3f}")
    if args.sample:
        top = best_per_spread(sample).nlargest(1, "objective").iloc[0]
        sampled = sample[sample["status"] == "ok"]
        print(f"sample: best {top['objective']:.4g} ({top['gait']}, offsets within "
              f"{top['spread']:g} of the period), {int((sampled['objective'] > plain).sum())} "
              f"of {len(sampled)} finished patterns above the best synchronous gait")
    return table
