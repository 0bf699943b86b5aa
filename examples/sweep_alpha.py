"""Sweep the jet coefficient α for two gaits in one batch: a table (CSV) and a plot.

    python examples/sweep_alpha.py                       # 9 values × 2 gaits, 3 cycles (~1 min)
    EXAMPLE_QUICK=1 python examples/sweep_alpha.py       # 3 values, 0.3 s (seconds)

The plot needs matplotlib (pip install -e ".[plots]").

Writes sweep_alpha.csv (one row per robot: its parameters and the simulate summary) and
sweep_alpha.png (drawn from that CSV) into the current folder.
"""
import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

import taichi_star as ts  # noqa: E402

quick = bool(os.environ.get("EXAMPLE_QUICK"))
alphas = np.linspace(0.0, 2.0, 3 if quick else 9)                     # jet coefficient, 1
gaits = ["A1+A2", "A1+A3"]
params = [ts.StarParams(gait=gait, alpha=alpha) for gait in gaits for alpha in alphas]
duration = 0.3 if quick else 3 * params[0].period                     # s
result = ts.simulate(params, duration, progress=not quick)            # one batch, one engine
table = result.summary                                                # one row per robot
assert (table.status == "ok").all(), table[table.status != "ok"]
result.to_csv("sweep_alpha.csv")                                      # with its provenance sidecar

table = pd.read_csv("sweep_alpha.csv")                                # plot from the CSV only
fig, ax = plt.subplots(figsize=(5, 3.5), layout="constrained")
for gait, rows in table.groupby("gait"):
    ax.plot(rows.alpha, rows.signed_speed_mm_s, "o-", label=gait)
ax.axhline(0.0, color="k", lw=0.5)
ax.set_xlabel("jet coefficient α")
ax.set_ylabel("mean speed along the gait's forward direction (mm/s)")
ax.set_title(f"{duration:g} s from rest, paper model", fontsize=9)
ax.legend()
fig.savefig("sweep_alpha.png", dpi=120)
print(table[["gait", "alpha", "signed_speed_mm_s"]].to_string(index=False))
