"""Step a batch of 64 robots by hand: each fires its own actuators every actuation period.

    python examples/step_batch.py                      # 3 periods of 3.15 s at h = 1 ms (~1 min)
    STEP_BATCH_QUICK=1 python examples/step_batch.py   # one 0.2-s step at h = 5 ms (seconds)
"""
import os

import numpy as np

import taichi_star as ts

quick = bool(os.environ.get("STEP_BATCH_QUICK"))
period = 0.2 if quick else 3.15                                       # s between commands
solver = ts.SolverConfig(dt=5e-3 if quick else 1e-3)                  # s per step
robots = ts.Simulator([ts.StarParams.preset("paper")] * 64, solver)   # 64 robots, one engine
choices = np.random.default_rng(0).random((64, 8)) < 0.4              # each robot's actuators
for _ in range(1 if quick else 3):
    robots.fire(choices)                                              # fire now...
    robots.advance(period)                                            # ...and swim one period
state = robots.state()
print(state[["centroid_x_mm", "centroid_y_mm", "heading_deg"]].describe().round(2))
print(f"{len(state)} robots at t = {state.t_s.max():.2f} s, {int(robots.ok.sum())} running")
