"""Drive one robot towards a goal by looking one actuation period ahead with the full model.

Every period the robot's present (shape, velocities, actuators still hot) is copied into one
robot per candidate gait (`Simulator.copy_state`), each fires its gait and swims the period in
the same batch, and the robot then takes the future of the candidate that ends nearest the goal
(copied back): no table of motion primitives, every candidate simulated from the robot's own
state. Writes lookahead.csv (one row per period: the gait chosen, where it ends). The library's
controller, `taichi_star.lookahead.lookahead_drive` (`python -m studies plan --lookahead`),
judges each candidate where it comes to rest and stops firing within a tolerance.

    python examples/lookahead.py                   # 255 gaits and a glide, 4 periods (~1 min)
    EXAMPLE_QUICK=1 python examples/lookahead.py   # 8 single actuators and a glide (seconds)
"""
import os

import numpy as np
import pandas as pd

import taichi_star as ts
from taichi_star.lookahead import every_gait

quick = bool(os.environ.get("EXAMPLE_QUICK"))
params = ts.StarParams.preset("paper")
solver = ts.SolverConfig(dt=5e-3 if quick else 1e-3)
goal_mm = np.array([-20.0, -30.0])                   # from the start, in the robot's frame
# the glide and every gait (quick: the glide and the eight single actuators)
names = ["none"] + [f"A{m}" for m in range(1, 9)] if quick else every_gait()

robots = ts.Simulator([params] * (1 + len(names)), solver)   # the robot, then its candidates
rows = []
for period in range(1, 3 if quick else 5):
    robots.copy_state(0)                                     # each candidate: the robot now
    robots.fire(["none"] + names)                            # its own gait (the robot: none)
    robots.advance(params.period)
    state = robots.state().iloc[1:]
    ends = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
    distance = np.where(state["status"] == "ok", np.hypot(*(ends - goal_mm).T), np.inf)
    best = int(np.argmin(distance))
    robots.copy_state(1 + best, to=0)                        # the robot lives that future
    rows.append({"period": period, "gait": names[best], "x_mm": ends[best, 0],
                 "y_mm": ends[best, 1], "distance_mm": distance[best]})
    print(f"period {period}: {names[best]:>8} to ({ends[best, 0]:6.2f}, {ends[best, 1]:6.2f}) mm,"
          f" {distance[best]:5.2f} mm from the goal")
pd.DataFrame(rows).to_csv("lookahead.csv", index=False)
