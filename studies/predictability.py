"""Predictability: which gaits' speeds the measured trials determine, at one model point, and
how far each measured gait's speed lies from the prediction there.

    python -m studies predictability [--preset identified|paper|accurate] [--set NAME=VALUE ...]
                                     [--parameters alpha,drag_perpendicular,...]
                                     [--gaits paper|A1,A1+A2,...] [--predict A2,A3,...]
                                     [--window 1:3] [--predict-window 4:6]
                                     [--trial-sigma MM] [--max-trials K] [--dt S]
                                     [--out DIR] [--quick]

A model fitted to the measured trials is judged on the gaits it was not fitted to. Whether it
can predict one at all is a question of the data before it is one of the model: a gait whose
speed moves with parameter combinations that the other gaits leave free is not predicted by
any fit to them, whatever the model. This study answers that question locally, with one run:
the measured gaits (`--gaits`) and the gaits to predict (`--predict`) simulated at the model
point (`--preset`/`--set`) with the exact sensitivities of `--parameters`, over the cycle
window `--window` from rest. `identification.gait_predictions` then forms, from the
trajectory objective's residuals and their Jacobian (each trial's phase fitted at the point),
the Gauss-Newton covariance of the parameters fitted to every measured gait, and to every
measured gait but one, and carries it to each gait's speed along its forward axis over
`--predict-window` (default the fit's window; a later one, e.g. 4:6, asks what the fit says of
cycles it did not see, the measured speed read there with the phase fitted on the fit's
window; `identification.prediction_uncertainty`): a standard error, or "undetermined" where
the speed moves along directions the fitted gaits do not resolve (`UNCERTAINTY_RCOND`,
`UNCERTAINTY_SHARE`). The point is not refitted: a held-out row keeps the speed of the point
fitted with every gait, and says how far the other gaits pin down what the held-out one needs,
not where a fit without it would land (model_select's cold folds do that, at 18-26 minutes
for a form's four folds at both stages). The standard errors are of the simulated speed: they
take the curve residuals as independent (samples of one measured curve are correlated, so
they are lower bounds) and leave out the measured speed's own scatter from cycle to cycle. The
measured speed is the distance covered (the tracks have no robot axes), signed by the paper's
direction; the simulated one is along the gait's forward axis, so a simulated robot that veers
off its axis counts as slow (`distance_speed_mm_s` gives its distance covered).

Which trial to measure next: the gaits of `--predict` are the candidate trials. For each, alone,
and for all of them together, `identification.trial_design` takes its trial as made (its curve
rows in every fit, spread `--trial-sigma` mm, default the measured trials' median σ at the
point, residuals scattering as the fit's own) and says again what each fit determines: a
held-out gait that becomes determined is one that trial would let the model predict.
`--max-trials K`: every set of at most K candidates instead, the smaller first (the fewest
trials that determine each gait; K at least their number: every subset).

Writes `predictability.csv` (one row per gait and role, `identification.PREDICTION_COLUMNS`
and the gait's simulation status), `predictability_parameters.csv`
(`identification.parameter_uncertainty` of the fit on every measured gait: which of
`--parameters` they determine) and `predictability.png` (per gait and role the predicted speed
with two standard errors, the measured one beside it), and, with gaits to predict,
`predictability_design.csv` (`identification.DESIGN_COLUMNS`, with each gait's simulation
status), `predictability_design_summary.csv` (`identification.design_summary`: per set of
trials, the held-out gaits it determines and the widest of their standard errors),
`predictability_design_parameters.csv` (`identification.parameter_design`: what the
fit on every measured gait would determine of `--parameters` with those trials) and
`predictability_design.png` (two standard errors of each held-out and unmeasured gait's speed
against the trials added) and `predictability_design_parameters.png` (each parameter's relative
standard error against them), each table with its provenance sidecar.

--quick: gaits A1+A2 and A1+A3, A2 predicted, α and C⊥, cycle 1, 2-ms steps.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from taichi_star import Gait, identification, simulate
from taichi_star.sensitivities import parse_directions

from . import cli, identify

DESCRIPTION = ("Predictability: which gaits' speeds the measured trials determine at a model "
               "point (a linearised leave-one-gait-out on the exact sensitivities), against the "
               "measured speeds, and which trials not yet made would determine the rest.")
IDENTIFIED_FORM = ("alpha,drag_perpendicular,cylinder_drag,actuator_gains[0],actuator_gains[1],"
                   "actuator_gains[2],actuator_gains[3],actuator_gains[4]")
"""The `identified` preset's fitted parameters (model_select's `gains_with_a1`: α, C⊥, C_c and
the gains of A1–A5), by Python's index as `simulate` names them."""
SINGLE_ACTUATORS = "A2,A3,A4,A5"
"""The default gaits to predict: each fires one of the actuators whose gain the identified form
fits, alone; no measured trial does (A1 is measured)."""
QUICK = {"gaits": "A1+A2,A1+A3", "predict": "A2", "parameters": "alpha,drag_perpendicular",
         "window": "1:1"}
ROLE_ORDER = ("fitted", "held_out", "unmeasured")
ROLE_COLOURS = {"fitted": "tab:blue", "held_out": "tab:orange", "unmeasured": "tab:green"}


def build_parser():
    parser = cli.StudyParser("predictability", DESCRIPTION)
    parser.add_argument("--parameters", default=IDENTIFIED_FORM, quick=QUICK["parameters"],
                        help="the fitted parameters, a comma list of StarParams fields as "
                             "simulate's sensitivities name them (an actuator by its Python "
                             "index: actuator_gains[0] is A1's; default: the identified "
                             "preset's form)")
    parser.add_argument("--gaits", default="paper", quick=QUICK["gaits"],
                        help="the measured gaits fitted: paper (all five) or a comma list, at "
                             "least two")
    parser.add_argument("--predict", default=SINGLE_ACTUATORS, quick=QUICK["predict"],
                        help="unmeasured gaits to predict from every measured one, a comma list "
                             "of gaits with a forward axis, or none")
    parser.add_argument("--window", default="1:3", quick=QUICK["window"],
                        help="the cycle window FIRST:LAST (1-based, from rest) of the fit")
    parser.add_argument("--predict-window", default=None,
                        help="the cycle window FIRST:LAST of the speeds predicted (default: "
                             "--window's)")
    parser.add_argument("--trial-sigma", default=None,
                        help="the spread (mm, at least the tracking floor 0.05) expected of a "
                             "candidate trial, each --predict gait's, taken as made in the "
                             "design table (default: the measured trials' median spread at "
                             "the point)")
    parser.add_argument("--max-trials", type=int, default=None, metavar="K",
                        help="the design table over every set of at most K of the --predict "
                             "gaits, the smaller first (default: each alone and all together)")
    cli.add_model_flags(parser, fixed=("gait",), preset="identified")
    cli.add_dt_flag(parser)
    return parser


def parse_window(text: str, flag: str = "--window"):
    """FIRST:LAST -> (first, last) (StudyArgumentError naming `flag`)."""
    parts = text.split(":")
    if len(parts) != 2 or not all(part.strip().isdigit() for part in parts):
        raise cli.StudyArgumentError(f"{flag}: expected FIRST:LAST, two whole numbers, e.g. "
                                     f"1:3, got {text!r}")
    try:
        return identification.check_window((int(parts[0]), int(parts[1])))
    except ValueError as error:
        raise cli.StudyArgumentError(f"{flag}: {error}") from None


def predicted_gaits(text: str, measured) -> list:
    """--predict -> canonical gait names: none, or gaits that are not measured and have a
    forward axis (a gait with none, e.g. all eight, has no speed to predict)."""
    if text.strip().lower() == "none":
        return []
    if "none" in [item.strip().lower() for item in text.split(",")]:
        raise cli.StudyArgumentError(f"--predict {text}: none stands alone (no gait to "
                                     f"predict), not in a list")
    gaits = cli.resolve_gaits(text, "--predict")
    for gait in gaits:
        if gait in measured:
            raise cli.StudyArgumentError(f"--predict {gait}: it is one of --gaits (measured "
                                         f"gaits are held out of the fit in turn already)")
        if Gait.parse(gait).forward is None:
            raise cli.StudyArgumentError(f"--predict {gait}: a gait with no forward axis (its "
                                         f"symmetry leaves no direction to swim)")
    return gaits


def check_design_size(max_trials: int, candidates: int):
    """--max-trials: a whole number >= 1 whose sets of candidate trials number at most
    `identification.MAX_DESIGN_SETS` (StudyArgumentError naming it, before any compute)."""
    if max_trials < 1:
        raise cli.StudyArgumentError(f"--max-trials must be >= 1, got {max_trials}")
    sets = identification.design_set_count(candidates, max_trials)
    if sets > identification.MAX_DESIGN_SETS:
        raise cli.StudyArgumentError(
            f"--max-trials {max_trials} over the {candidates} --predict gaits asks for {sets} "
            f"sets of trials, more than {identification.MAX_DESIGN_SETS}: lower it or predict "
            f"fewer gaits")


def parameter_values(base, names) -> np.ndarray:
    """The values (P,) of `names` (simulate's labels) in the model `base`."""
    return np.array([direction.value(base) for direction in parse_directions(list(names))])


@dataclass(frozen=True)
class Ran:
    """What the fits can use of a run with the sensitivities (`runs_that_ran`)."""

    runs: dict          # gait -> identification.SimulatedRun, the gaits that ran
    status: dict        # gait -> "ok", or its failure and time ("diverged at 1.23 s")
    failed: list        # the gaits that did not run to the end
    trials: dict        # measured gait -> identification.Trial, those that ran
    derivatives: dict   # gait -> (n_records, 2, P) record derivatives, those that ran


def runs_that_ran(result, params, measured, names) -> Ran:
    """The run's gaits that ran to the end, with their measured trials and derivatives, and
    every gait's status; a warning names each failure (once). StudyOutputError (one line) with
    fewer than two measured gaits that ran."""
    gaits = [p.gait for p in params]
    runs = dict(zip(gaits, identification.result_runs(result, params)))
    summary = result.summary
    status = {}
    for b, gait in enumerate(gaits):
        row = summary.iloc[b]
        status[gait] = ("ok" if runs[gait] is not None else
                        f"{row['status']} at {row['failure_time_s']:.3g} s")
    failed = [gait for gait in gaits if status[gait] != "ok"]
    for gait in failed:
        warnings.warn(f"{gait}: the simulation {status[gait]}; left out of the fits and "
                      f"predictions", RuntimeWarning)
    ran = [gait for gait in gaits if gait not in failed]
    trials = {gait: identification.measured_trial(gait) for gait in measured if gait in ran}
    if len(trials) < 2:
        raise cli.StudyOutputError(f"fewer than two measured gaits ran ({', '.join(failed)} "
                                   f"failed): nothing to fit")
    derivatives = {gait: identification.record_derivatives(result.trajectory_sensitivities,
                                                           gaits.index(gait), names)
                   for gait in ran}
    return Ran({g: runs[g] for g in ran}, status, failed, trials, derivatives)


def _with_failures(table, ran: Ran, measured, cycles):
    """The table with each failed gait's rows (its status, role and window, no numbers) after
    the others."""
    table.insert(table.columns.get_loc("gait") + 1, "status",
                 [ran.status[g] for g in table["gait"]])
    left_out = [{"gait": gait, "status": ran.status[gait], "role": role,
                 "first_cycle": cycles[0], "last_cycle": cycles[1]}
                for gait in ran.failed
                for role in (("fitted", "held_out") if gait in measured else ("unmeasured",))]
    if ran.failed:
        table = pd.concat([table, pd.DataFrame(left_out)], ignore_index=True)
    return table


def predictability_table(ran: Ran, measured, names, values, window,
                         predict_window=None) -> tuple:
    """(predictions, parameter uncertainty) of the gaits that ran (`runs_that_ran`): the rows
    of `identification.gait_predictions` with each gait's simulation status. A gait whose run
    failed keeps its rows, with the failure and its time in `status` and no numbers, and every
    fit uses the measured gaits that ran."""
    table = identification.gait_predictions(ran.runs, ran.derivatives, ran.trials, values,
                                            window, predict_cycles=predict_window)
    table = _with_failures(table, ran, measured,
                           window if predict_window is None else predict_window)
    residuals, jacobian, _ = identification.objective_residuals(
        {g: ran.runs[g] for g in ran.trials}, ran.derivatives, ran.trials, window)
    parameters = identification.parameter_uncertainty(residuals, jacobian, names, values)
    return table, parameters


def design_tables(ran: Ran, measured, candidates, names, values, window, predict_window=None,
                  trial_sigma=None, max_trials=None) -> tuple:
    """(`identification.trial_design`, `identification.parameter_design`) of the candidate
    trials that ran; the first with each gait's simulation status, a failed gait keeping rows
    with no numbers, once, under no added trial ("none")."""
    candidates = [gait for gait in candidates if gait in ran.runs]
    table = identification.trial_design(ran.runs, ran.derivatives, ran.trials, values,
                                        candidates, window, predict_cycles=predict_window,
                                        added_sigma_mm=trial_sigma, max_trials=max_trials)
    table = _with_failures(table, ran, measured,
                           window if predict_window is None else predict_window)
    table["added_trials"] = table["added_trials"].fillna("none")
    parameters = identification.parameter_design(ran.runs, ran.derivatives, ran.trials, names,
                                                 values, candidates, window,
                                                 added_sigma_mm=trial_sigma,
                                                 max_trials=max_trials)
    return table, parameters


def plot_predictability(csv_path, png_path):
    table = pd.read_csv(csv_path)
    table = table[table["predicted_speed_mm_s"].notna()]
    plt = cli.use_agg()
    fig, ax = plt.subplots(figsize=(7.5, 0.42 * len(table) + 1.6))
    labels = []
    finite = table.loc[np.isfinite(table["standard_error_mm_s"])]
    spans = pd.concat([finite["predicted_speed_mm_s"] + 2 * sign * finite["standard_error_mm_s"]
                       for sign in (-1, 1)] + [table["measured_speed_mm_s"].dropna(),
                                               table["predicted_speed_mm_s"]])
    low, high = float(spans.min()), float(spans.max())
    margin = 0.1 * (high - low or 1.0)
    low, high = low - margin, high + margin
    for y, row in enumerate(table.itertuples()):
        colour = ROLE_COLOURS[row.role]
        if math.isfinite(row.standard_error_mm_s):
            ax.errorbar(row.predicted_speed_mm_s, y, xerr=2 * row.standard_error_mm_s, fmt="o",
                        color=colour, capsize=3, ms=4)
        else:  # the data leave it undetermined: the whole line
            ax.plot([low, high], [y, y], color=colour, ls=":", lw=1)
            ax.plot(row.predicted_speed_mm_s, y, "o", color=colour, ms=4, mfc="white")
        if not math.isnan(row.measured_speed_mm_s):
            ax.plot(row.measured_speed_mm_s, y, "kx", ms=6)
        labels.append(f"{row.gait} ({row.role.replace('_', ' ')})")
    ax.set_yticks(range(len(table)), labels, fontsize=8)
    ax.invert_yaxis()
    ax.axvline(0.0, color="0.7", lw=0.8)
    ax.set_xlim(low, high)
    first, last = int(table["first_cycle"].iloc[0]), int(table["last_cycle"].iloc[0])
    ax.set_xlabel(f"speed over cycles {first}-{last}, mm/s (simulated: along the gait's forward "
                  f"axis; measured: the distance covered, signed by the paper's direction)",
                  fontsize=8)
    handles = [plt.Line2D([], [], color=ROLE_COLOURS[r], marker="o", ls="", label=r.replace(
        "_", " ")) for r in ROLE_ORDER if r in set(table["role"])]
    handles += [plt.Line2D([], [], color="k", marker="x", ls="", label="measured"),
                plt.Line2D([], [], color="0.4", ls=":", label="undetermined by the fit")]
    ax.legend(handles=handles, fontsize=7, loc="lower right")
    settings = cli.run_settings(csv_path, mesh=False)
    fitted = cli.written_provenance(csv_path).get("details", {}).get("window")
    on = f", fitted on cycles {fitted[0]}-{fitted[1]}" if fitted else ""
    ax.set_title(f"predicted speed ± 2 standard errors (lower bounds){on}"
                 + (f"\n{settings}" if settings else ""), fontsize=9)
    fig.tight_layout()
    return cli.save_figure(fig, png_path)


def _log_grid(values, texts, rows, columns, colour_label, column_width, rotation=0):
    """A grid of values (len(rows), len(columns)) coloured by log10 (blank where not a positive
    finite number), each cell's text over it, dark on the light (small) end of the colour map
    and light on the dark end; returns (figure, axes)."""
    plt = cli.use_agg()
    fig, ax = plt.subplots(figsize=(column_width * len(columns) + 3.2, 0.3 * len(rows) + 2.2))
    finite = np.isfinite(values) & (values > 0)
    shown = np.where(finite, np.log10(np.where(finite, values, 1.0)), np.nan)
    image = ax.imshow(shown, cmap="viridis_r", aspect="auto")
    for i in range(len(rows)):
        for j in range(len(columns)):
            light = finite[i, j] and image.norm(shown[i, j]) > 0.55
            ax.text(j, i, texts[i][j], ha="center", va="center", fontsize=7,
                    color="w" if light else "k")
    ax.set_xticks(range(len(columns)), columns, fontsize=7, rotation=rotation,
                  ha="right" if rotation else "center")
    ax.set_yticks(range(len(rows)), rows, fontsize=7)
    fig.colorbar(image, ax=ax, label=colour_label, shrink=0.8)
    return fig, ax


def plot_design(csv_path, png_path):
    """Two standard errors of each held-out and unmeasured gait's speed (columns) with the
    trials taken as made (rows): colour log10 of it, "undetermined" where the fits leave the
    speed free, * where the gait's own trial is among those taken as made."""
    table = pd.read_csv(csv_path)
    table = table[table["role"].isin(("held_out", "unmeasured", "added"))
                  & table["predicted_speed_mm_s"].notna()]
    sets = list(dict.fromkeys(table["added_trials"]))
    gaits = list(dict.fromkeys(table["gait"]))
    errors = np.full((len(sets), len(gaits)), np.nan)
    own = np.zeros_like(errors, dtype=bool)
    for row in table.itertuples():
        i, j = sets.index(row.added_trials), gaits.index(row.gait)
        errors[i, j] = 2 * row.standard_error_mm_s
        own[i, j] = row.role == "added"
    texts = [[("undet." if np.isinf(error) else f"±{error:.2g}") + (" *" if mine else "")
              for error, mine in zip(error_row, own_row)]
             for error_row, own_row in zip(errors, own)]
    held = set(table.loc[table["role"] == "held_out", "gait"])
    fig, ax = _log_grid(errors, texts, sets,
                        [f"{g}\n({'held out' if g in held else 'unmeasured'})" for g in gaits],
                        "log10 of 2 s.e., mm/s", 1.05)
    ax.set_ylabel("trials taken as made (* the gait's own)", fontsize=8)
    sigma = table["added_sigma_mm"].dropna()
    spread = f"; a trial's spread {sigma.iloc[0]:.3g} mm" if len(sigma) else ""
    first, last = int(table["first_cycle"].iloc[0]), int(table["last_cycle"].iloc[0])
    settings = cli.run_settings(csv_path, mesh=False)
    ax.set_title(f"2 s.e. of the speed over cycles {first}-{last} (lower bounds){spread}"
                 + (f"\n{settings}" if settings else ""), fontsize=8)
    fig.tight_layout()
    return cli.save_figure(fig, png_path)


def plot_parameter_design(csv_path, png_path):
    """Each parameter's relative standard error (columns, %) with the trials taken as made
    (rows): colour log10 of it, "not id." where the fit would not determine it."""
    table = pd.read_csv(csv_path)
    sets = list(dict.fromkeys(table["added_trials"]))
    names = list(dict.fromkeys(table["parameter"]))
    errors = np.full((len(sets), len(names)), np.nan)
    for row in table.itertuples():
        errors[sets.index(row.added_trials), names.index(row.parameter)] = (
            100 * row.relative_standard_error if row.identifiable else math.inf)
    texts = [["not id." if np.isinf(error) else f"{error:.2g} %" for error in error_row]
             for error_row in errors]
    fig, ax = _log_grid(errors, texts, sets, names,
                        "log10 of the relative standard error, %", 0.95, rotation=30)
    ax.set_ylabel("trials taken as made", fontsize=8)
    settings = cli.run_settings(csv_path, mesh=False)
    ax.set_title("the parameters' relative standard errors, the fit on every measured gait "
                 "(lower bounds)" + (f"\n{settings}" if settings else ""), fontsize=8)
    fig.tight_layout()
    return cli.save_figure(fig, png_path)


def main(argv=None):
    args = cli.parse(build_parser(), argv)
    base = cli.base_params(args)
    names = cli.sensitivity_parameters(args.parameters, "--parameters")
    measured = identify.measured_gaits(args.gaits)
    if len(measured) < 2:
        raise cli.StudyArgumentError(f"--gaits: at least two measured gaits (one held out, one "
                                     f"fitted), got {', '.join(measured)}")
    predict = predicted_gaits(args.predict, measured)
    window = parse_window(args.window)
    predict_text = args.window if args.predict_window is None else args.predict_window
    predict_window = parse_window(predict_text, "--predict-window")
    for flag, given in (("--max-trials", args.max_trials), ("--trial-sigma", args.trial_sigma)):
        if given is not None and not predict:
            raise cli.StudyArgumentError(f"{flag}: only with gaits to --predict (the candidate "
                                         f"trials of the design table)")
    if args.max_trials is not None:
        check_design_size(args.max_trials, len(predict))
    trial_sigma = None
    if args.trial_sigma is not None:
        trial_sigma = cli.parse_number(args.trial_sigma, "--trial-sigma")
        if trial_sigma < identification.DISPLACEMENT_FLOOR_MM:
            raise cli.StudyArgumentError(
                f"--trial-sigma must be >= {identification.DISPLACEMENT_FLOOR_MM} mm (the "
                f"tracking noise, where a measured trial's spread is floored), got "
                f"{trial_sigma}")
    trials = identification.measured_trials(measured)
    identify.check_trials_cover(trials, window, args.window, "--window")
    # the measured speeds of the later window are read at the phase fitted on --window
    identify.check_trials_cover(trials, predict_window, predict_text, "--predict-window")
    solver = cli.solver(args)
    duration = max(window[1], predict_window[1]) * base.period
    cli.check_run(f"--window {args.window}, --predict-window {predict_text} "
                  f"({duration:.3g} s)", duration, solver)
    values = parameter_values(base, names)
    params = [base.replace(gait=gait) for gait in measured + predict]
    out = cli.Output(args, argv or [], model={"preset": args.preset, "params": base},
                     solver=solver, extra={"parameters": names, "window": list(window),
                                           "predict_window": list(predict_window),
                                           "trial_sigma_mm": trial_sigma,
                                           "max_trials": args.max_trials})
    result = simulate(params, duration, solver, arch=args.arch,
                      record_interval_s=identify.RECORD_INTERVAL_S, sensitivities=names,
                      progress=not args.no_progress)
    ran = runs_that_ran(result, params, measured, names)
    table, parameters = predictability_table(ran, measured, names, values, window,
                                             predict_window)
    csv_path = out.write_csv(table, "predictability.csv")
    out.write_csv(parameters, "predictability_parameters.csv")
    out.wrote(plot_predictability(csv_path, out.path("predictability.png")))
    if predict:
        design, parameter_design = design_tables(ran, measured, predict, names, values, window,
                                                 predict_window, trial_sigma, args.max_trials)
        design_path = out.write_csv(design, "predictability_design.csv")
        out.write_csv(identification.design_summary(design),
                      "predictability_design_summary.csv")
        parameters_path = out.write_csv(parameter_design,
                                        "predictability_design_parameters.csv")
        out.wrote(plot_design(design_path, out.path("predictability_design.png")))
        out.wrote(plot_parameter_design(parameters_path,
                                        out.path("predictability_design_parameters.png")))
    out.report()
    return table
