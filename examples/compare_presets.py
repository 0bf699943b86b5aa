"""The paper's five gaits under both presets, next to the measured robot (the Fig. 4c table).

    python examples/compare_presets.py                   # 3 cycles each (~10 s)
    EXAMPLE_QUICK=1 python examples/compare_presets.py   # 0.3 s each (seconds)

"paper" is the model and scheme as published; "accurate" adds material damping and
second-order joints and steps adaptively (see the documentation's model page).
"""
import os

import pandas as pd

import taichi_star as ts
from taichi_star.experiment import PAPER_GAITS, compare_with_experiment
from taichi_star.timegrid import interval_for_count

quick = bool(os.environ.get("EXAMPLE_QUICK"))
tables = []
for preset in ("paper", "accurate"):
    params = [ts.StarParams.preset(preset, gait=gait) for gait in PAPER_GAITS]
    duration = 0.3 if quick else 3 * params[0].period                 # s
    solver = ts.SolverConfig.preset(preset)
    # about 150 records a run, as the fig4c study takes them: adaptive steps end on every
    # record time, so the accurate preset's speeds depend on them in the third decimal
    summary = ts.simulate(params, duration, solver=solver,
                          record_interval_s=interval_for_count(duration, 150, solver.dt)).summary
    table = compare_with_experiment(summary)                          # sim vs measured, mm/s
    tables.append(table.assign(preset=preset))
table = pd.concat(tables, ignore_index=True)
print(table.pivot(index="gait", columns="preset", values="sim_signed_speed_mm_s")
      .join(table.groupby("gait").exp_speed_mm_s.first().rename("measured |speed|"))
      .reindex(list(PAPER_GAITS)).round(3).to_string())
print("directions as in the paper:",
      table.groupby("preset").direction_matches.sum().astype(int).to_dict(), "of 5")
