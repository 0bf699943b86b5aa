"""Strokes: when each measured trial's pulses fire, read off its track, against the phase the
trajectory fit chooses.

    python -m studies strokes [--preset identified|paper|accurate] [--set NAME=VALUE ...]
                              [--cycles 3] [--window 0.1] [--out DIR] [--quick]

The videos do not record when the heating pulses fire, so the trajectory objective fits that
phase per trial to the simulation it compares (`identification.align_phase`). The tracks show
it themselves: at each stroke the robot's centroid jumps. `identification.strokes` finds, in
every period of a trial, where the stroke begins: the first `--window` whose move rises to
halfway from the track's typical move to that period's farthest (`Strokes.cycle_onsets_mm`),
and their circular mean phase. The strokes also drift from period to period where the pulses
do not come exactly every 3.15 s: where more than half lie on one line (`Strokes.periodic`),
its slope gives their period as measured. The same reading of the simulated path of the
`--preset` model (`--cycles` from rest, and a window more to read the last period's) gives the
model's own lag from a firing to the onset of its stroke; the line over cycles 1–3 less that
lag is the firing that the track implies for that model (`identification.stroke_aligned_phase`),
set beside the phase that the trajectory fit chooses for it on cycles 1–3
(`identification.trajectory_objective`).

Writes `strokes.csv` (one row per gait: the measured strokes and their period, the period read
with the onset a tenth lower and higher up the rise (`ONSET_SHARES_CHECKED`), the model's,
the jump of the model's hub, the implied firing phase, the fitted phase and the gap between
them), `strokes_moves.csv` (every measured move: gait, cycle, phase_s in the period from the
track's start, move_mm, the period's onset_mm and whether its stroke begins there) and
`strokes.png` (per gait, the moves folded over the period with where each period's stroke
begins and its onset marked, the stroke phase, the implied firing and the fitted phase), each
with its provenance sidecar.

--quick: gait A1+A2, 2-ms steps.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from taichi_star import identification, metrics, simulate
from taichi_star.experiment import PAPER_GAITS

from . import cli, identify

DESCRIPTION = ("Strokes: when each measured trial's pulses fire, read off its track (the "
               "centroid's jumps), against the phase the trajectory fit chooses.")
QUICK_GAITS = ("A1+A2",)
ONSET_SHARES_CHECKED = (0.4, 0.6)
"""The onset shares at which each trial's pulse period is read again beside the default's
(`pulse_period_low_onset_s`, `pulse_period_high_onset_s`): how much the period depends on how
far up its rise a stroke is said to begin (A1+A3's the most: an audit, 2026-12-05)."""
MODEL_COLUMNS = ("model_stroke_phase_s", "model_consistent_cycles", "model_cycles",
                 "model_jump_mm", "model_hub_jump_mm", "model_typical_move_mm", "firing_phase_s",
                 "fitted_phase_s", "phase_gap_s")
"""Columns of `strokes.csv` that need the simulated run (NaN where it failed)."""


def build_parser():
    parser = cli.StudyParser("strokes", DESCRIPTION)
    parser.add_argument("--window", type=float, default=identification.STROKE_WINDOW_S,
                        help=f"window of a stroke's jump, s, in (0, T/2] (default "
                             f"{identification.STROKE_WINDOW_S:g}: six video frames)")
    # the identified model's strokes are the ones compared with the measured (strokes' help
    # said "default paper" while it ran the identified preset: an audit)
    cli.add_model_flags(parser, fixed=("gait", "period"), preset="identified")
    cli.add_dt_flag(parser)
    cli.add_cycles_flag(parser, default=3.0, quick_s=None)
    return parser


def strokes_table(trials, runs, hub_paths, fits: pd.DataFrame, window_s: float):
    """(one row per gait, every measured move) from the measured trials, the simulated runs
    (`identification.SimulatedRun`, same gaits; None for a failed run, whose model columns are
    NaN), the paths of their hubs (`identification.CentroidPath` per gait that ran) and the
    trajectory fit's table (a row per gait that ran)."""
    rows, moves = [], []
    for gait, trial in trials.items():
        period = trial.path.period_s
        measured = identification.strokes(trial.path, window_s)
        row = {"gait": gait, "cycles": measured.cycles, "stroke_phase_s": measured.phase_s,
               "consistent_cycles": measured.consistent_cycles, "jump_mm": measured.jump_mm,
               "typical_move_mm": measured.typical_mm,
               "jump_ratio": measured.jump_mm / measured.typical_mm,
               "on_line_cycles": measured.on_line_cycles, "periodic": measured.periodic,
               "line_phase_s": measured.line_phase_s, "drift_s": measured.drift_s,
               "pulse_period_s": trial.path.period_s + measured.drift_s}
        for column, share in zip(("pulse_period_low_onset_s", "pulse_period_high_onset_s"),
                                 ONSET_SHARES_CHECKED):
            row[column] = period + identification.strokes(trial.path, window_s,
                                                          onset_share=share).drift_s
        row.update(dict.fromkeys(MODEL_COLUMNS, math.nan))
        if runs[gait] is not None:
            # a simulation has no tracking noise: every stroke is read, its first from rest too
            model = identification.strokes(runs[gait].path, window_s, from_rest=True,
                                           min_jump_ratio=1.0)
            firing = identification.stroke_aligned_phase(
                runs[gait], trial, identification.TRAINING_CYCLES, measured,
                window_s) if measured.periodic else math.nan
            fitted = float(fits.loc[fits["gait"] == gait, "phase_s"].iloc[0])
            row.update({"model_stroke_phase_s": model.phase_s,
                        "model_consistent_cycles": model.consistent_cycles,
                        "model_cycles": model.cycles, "model_jump_mm": model.jump_mm,
                        "model_hub_jump_mm": identification.strokes(
                            hub_paths[gait], window_s, from_rest=True,
                            min_jump_ratio=1.0).jump_mm,
                        "model_typical_move_mm": model.typical_mm, "firing_phase_s": firing,
                        "fitted_phase_s": fitted,
                        "phase_gap_s": float(identification.circular_difference(
                            fitted, firing, period))})
        rows.append(row)
        times, move = identification.window_moves(trial.path, window_s)
        offset = times - trial.path.t_s[0]
        cycle = (offset // period).astype(int) + 1
        read = cycle <= measured.cycles  # the last, partial period has no stroke read
        onset = np.full(times.size, math.nan)
        onset[read] = measured.cycle_onsets_mm[cycle[read] - 1]
        moves.append(pd.DataFrame({"gait": gait, "cycle": cycle, "phase_s": offset % period,
                                   "move_mm": move, "onset_mm": onset,
                                   "stroke": np.isin(times, measured.stroke_times_s)}))
    return pd.DataFrame(rows), pd.concat(moves, ignore_index=True)


def hub_paths(result, runs) -> dict:
    """The path of the hub (`metrics.HUB_NODE`, mm) of every gait that ran, at its run's record
    times: the robot's central cylinder, the point a tracker may follow instead of the
    centroid. `runs`: {gait: `identification.SimulatedRun`, None where it failed} in the
    batch's order (the k-th gait is instance k of `result.shapes`, (records, B, N, 2) m)."""
    return {gait: identification.CentroidPath(
                run.path.t_s, *(metrics.METERS_TO_MM * result.shapes[:, instance,
                                                                    metrics.HUB_NODE].T),
                run.path.period_s)
            for instance, (gait, run) in enumerate(runs.items()) if run is not None}


def plot_strokes(csv_path, moves_path, png_path, period_s: float):
    table, moves = pd.read_csv(csv_path), pd.read_csv(moves_path)
    plt = cli.use_agg()
    fig, axes = plt.subplots(len(table), 1, figsize=(7.5, 1.9 * len(table) + 0.6),
                             sharex=True, squeeze=False)
    for ax, row in zip(axes[:, 0], table.itertuples()):
        gait_moves = moves[moves["gait"] == row.gait]
        ax.scatter(gait_moves["phase_s"], gait_moves["move_mm"], s=2, color="0.6",
                   label="move within the window")
        starts = gait_moves[gait_moves["stroke"]]
        ax.scatter(starts["phase_s"], starts["onset_mm"], s=14, marker="_", color="0.2",
                   label="its period's onset")
        ax.scatter(starts["phase_s"], starts["move_mm"], s=14, color="tab:red",
                   label="where each period's stroke begins")
        ax.axvline(row.stroke_phase_s, color="tab:red", lw=1, label="stroke phase (mean)")
        if row.periodic:
            ax.axvline(row.firing_phase_s, color="tab:blue", lw=1.2, ls="--",
                       label="firing implied, cycles 1-3")
        ax.axvline(row.fitted_phase_s, color="tab:green", lw=1.2, ls=":",
                   label="phase the fit chose, cycles 1-3")
        ax.set_ylabel("mm")
        reading = (f"pulses every {row.pulse_period_s:.3f} s; fit − implied "
                   f"{row.phase_gap_s:+.2f} s" if row.periodic
                   else "strokes on no period: no firing to imply")
        ax.set_title(f"{row.gait}: {row.on_line_cycles} of {row.cycles} strokes on their line "
                     f"(within {identification.STROKE_TOLERANCE_S:g} s); {reading}", fontsize=9)
    axes[-1, 0].set_xlim(0, period_s)
    axes[-1, 0].set_xlabel("time in the period from the track's start, s")
    axes[-1, 0].legend(fontsize=7, ncol=2, loc="upper right")  # the coast's moves are small
    settings = cli.run_settings(csv_path, mesh=False)
    fig.suptitle("measured strokes against the fitted phase" + (f"; {settings}" if settings
                                                                 else ""), fontsize=9)
    return cli.save_figure(fig, png_path)


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    base = cli.base_params(args)
    if not (math.isfinite(args.window) and 0 < args.window <= base.period / 2):
        raise cli.StudyArgumentError(f"--window must be in (0, {base.period / 2:g}] s (half "
                                     f"the period), got {args.window!r}")
    first, last = identification.TRAINING_CYCLES
    if args.cycles < last or args.cycles != int(args.cycles):
        raise cli.StudyArgumentError(f"--cycles must be a whole number >= {last} (the fit's "
                                     f"cycles {first}-{last}), got {args.cycles!r}")
    gaits = list(QUICK_GAITS if args.quick else PAPER_GAITS)
    params = [base.replace(gait=gait) for gait in gaits]
    solver = cli.solver(args)
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver)
    # a window and a record past the last period: its stroke is read too
    duration = args.cycles * base.period + args.window + identify.RECORD_INTERVAL_S
    result = simulate(params, duration, solver, arch=args.arch,
                      record_interval_s=identify.RECORD_INTERVAL_S, record_shapes=True,
                      progress=not args.no_progress)
    trials = identification.measured_trials(gaits)
    runs = dict(zip(trials, identification.simulated_runs(result.trajectory, list(trials),
                                                           [p.period for p in params])))
    ran = [gait for gait, run in runs.items() if run is not None]
    fits = identification.trajectory_objective({g: runs[g] for g in ran},
                                               {g: trials[g] for g in ran}) if ran else None
    table, moves = strokes_table(trials, runs, hub_paths(result, runs), fits, args.window)
    table.insert(1, "status", result.summary["status"].to_numpy())
    csv_path = out.write_csv(table, "strokes.csv")
    moves_path = out.write_csv(moves, "strokes_moves.csv")
    out.wrote(plot_strokes(csv_path, moves_path, out.path("strokes.png"), base.period))
    out.report()
    return table
