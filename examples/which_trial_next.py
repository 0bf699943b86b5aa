"""Which trial to measure next: what each candidate trial would let the model predict.

    python examples/which_trial_next.py                   # cycles 1-3, five candidates (~20 s)
    EXAMPLE_QUICK=1 python examples/which_trial_next.py   # cycle 1, two candidates (seconds)

The `identified` model has a gain per actuator, and a gain that only one measured gait moves
is free once that gait is held out: the other gaits cannot predict it. This script runs the
five measured gaits and the candidate trials once, with the exact sensitivities of the eight
fitted parameters, and asks `identification.trial_design` which held-out gaits each set of at
most two candidate trials would determine (the linearised fit with that trial taken as made,
at the measured trials' median spread), and how closely. Writes which_trial_next.csv (the
design table) and prints, per set, the held-out gaits left undetermined and the widest two
standard errors of the others; then the smallest sets that determine every held-out gait.
For the study with plots and provenance see `python -m studies predictability`.
"""
import os

import numpy as np

import taichi_star as ts
from taichi_star import identification

quick = bool(os.environ.get("EXAMPLE_QUICK"))
window = (1, 1) if quick else (1, 3)                            # cycles fitted, from rest
candidates = ["A2", "A4"] if quick else ["A2", "A3", "A4", "A5", "A2+A4"]
names = ["alpha", "drag_perpendicular", "cylinder_drag"] + [
    f"actuator_gains[{k}]" for k in range(5)]                   # the identified form, A1-A5
measured = list(identification.measured_trials())               # the five paper gaits

base = ts.StarParams.preset("identified")
params = [base.replace(gait=gait) for gait in measured + candidates]
result = ts.simulate(params, window[1] * base.period, ts.SolverConfig.preset("identified"),
                     record_interval_s=0.01, sensitivities=names)
runs = dict(zip(measured + candidates, identification.result_runs(result, params)))
assert all(run is not None for run in runs.values()), result.summary.status
derivatives = {gait: identification.record_derivatives(result.trajectory_sensitivities, b,
                                                        names)
               for b, gait in enumerate(measured + candidates)}
values = np.array([base.alpha, base.drag_perpendicular, base.cylinder_drag,
                   *base.actuator_gains[:5]])
design = identification.trial_design(runs, derivatives, identification.measured_trials(),
                                     values, candidates, window, max_trials=2)
design.to_csv("which_trial_next.csv", index=False)

summary = identification.design_summary(design)                # one row per set of trials
for row in summary.itertuples():
    print(f"{row.added_trials:>10}: undetermined {row.held_out_undetermined:<24} "
          f"widest 2 s.e. of the rest {2 * row.widest_held_out_standard_error_mm_s:.3f} mm/s")
complete = summary[summary.every_held_out_determined]
fewest = complete[complete.trials == complete.trials.min()]
print("smallest sets that determine every held-out gait:",
      "; ".join(fewest.added_trials) or "none within two trials")
