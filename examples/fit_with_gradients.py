"""Identify two parameters from swimming speeds with exact gradients: a twin experiment.

    python examples/fit_with_gradients.py                   # five gaits, one period (~15 s)
    EXAMPLE_QUICK=1 python examples/fit_with_gradients.py   # 0.3 s of swimming (seconds)

Needs scipy (pip install -e ".[studies]"). The "measured" speeds are the model's own at known
values of the jet coefficient α and the rods' perpendicular drag coefficient C⊥; a fit that
starts elsewhere must find them again. Every evaluation is one batch of the five Fig. 4c gaits
with the two exact sensitivities (`simulate(..., sensitivities=...)`), which give the
least-squares Jacobian; one derivative is checked against a central difference of two runs.
Prints the check, the fit's path and the recovered values. For the robot's real measurements
see `python -m studies gradient_fit`.
"""
import os

import numpy as np
from scipy.optimize import least_squares

import taichi_star as ts

quick = bool(os.environ.get("EXAMPLE_QUICK"))
gaits = ["A1", "A1+A2", "A1+A3", "A1+A4", "A1+A3+A5"]
names = ("alpha", "drag_perpendicular")                      # jet coefficient 1, C⊥ 1
true_values = np.array([1.1, 1.3])
start = np.array([0.8, 1.0])                                 # the paper preset's values
bounds = ([0.2, 0.5], [2.0, 2.0])
duration = 0.3 if quick else ts.StarParams().period          # s


def run(values, sensitivities=names):
    params = [ts.StarParams(gait=gait, **dict(zip(names, values))) for gait in gaits]
    result = ts.simulate(params, duration, sensitivities=sensitivities)
    assert (result.summary.status == "ok").all(), result.summary.status
    return result


target = run(true_values, ()).summary["signed_speed_mm_s"].to_numpy()   # mm/s per gait

# one derivative against a central difference of whole runs (h: 1e-4 of α)
result = run(start)
exact = result.sensitivity("signed_speed_mm_s", "alpha")               # (5,) mm/s per unit α
h = 1e-4
plus, minus = (run(start + [sign * h, 0.0], ()).summary["signed_speed_mm_s"].to_numpy()
               for sign in (1, -1))
difference = (plus - minus) / (2 * h)
print("d speed / d alpha, exact:     ", np.array2string(exact, precision=6))
print("central difference (h = 1e-4):", np.array2string(difference, precision=6))
print(f"largest relative difference: {np.max(np.abs(exact - difference) / np.abs(exact)):.1e}")

path = []
evaluated = {}


def evaluate(values):
    """(residuals (5,) mm/s, Jacobian (5, 2)) at `values`, one batch, kept for `jacobian`."""
    key = tuple(values)
    if key not in evaluated:
        result = run(values)
        speeds = result.summary["signed_speed_mm_s"].to_numpy()
        jacobian = np.column_stack([result.sensitivity("signed_speed_mm_s", name)
                                    for name in names])
        evaluated[key] = (speeds - target, jacobian)
        path.append((values.copy(), float(np.sum((speeds - target) ** 2))))
    return evaluated[key]


fit = least_squares(lambda values: evaluate(values)[0], start,
                    jac=lambda values: evaluate(values)[1], bounds=bounds, x_scale="jac",
                    xtol=1e-10, ftol=1e-12, gtol=1e-12, max_nfev=20)
for k, (values, cost) in enumerate(path):
    print(f"evaluation {k}: alpha = {values[0]:.6f}, drag_perpendicular = {values[1]:.6f}, "
          f"sum of squares = {cost:.3e} (mm/s)^2")
print(f"recovered: alpha = {fit.x[0]:.6f} (true {true_values[0]}), drag_perpendicular = "
      f"{fit.x[1]:.6f} (true {true_values[1]}), after {len(path)} evaluations")
