"""Diagnostics of a run that its summary cannot give, computed from its recorded shapes.

`jet_impulses(result)` (also `SimulationResult.jet_impulses()`): the impulse each inter-limb
space's jet gave the robot over the run, to see which spaces push which way and when (why a
firing pattern swims as it does: docs/results.md, "A sample of the whole landscape").
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from .gait import N_ACTUATORS
from .params import StarParams
from .reference import ReferenceSimulator

__all__ = ["check_jet_solver", "jet_impulses"]

ROUND_OFF = 1e-9
"""Relative tolerance within which the records' spacing must equal the time step (they are
sums of steps, rounded)."""


def check_jet_solver(solver) -> None:
    """ValueError unless `solver` (a SolverConfig) runs implicit Euler with fixed steps, the
    only runs whose jets `jet_impulses` recomputes as the engine applied them (elsewhere the
    engine's area rate is not the difference quotient of two recorded shapes)."""
    if solver.adaptive or solver.integrator != "euler":
        raise ValueError(f"jet_impulses needs implicit Euler with fixed steps (its area rates "
                         f"are the engine's only there), got integrator={solver.integrator!r}, "
                         f"adaptive={solver.adaptive}")


def jet_impulses(result) -> pd.DataFrame:
    """One row per instance and inter-limb space: instance, space (1..8: the space between two
    limbs whose arc holds actuator A<space>), impulse_x_n_s_m and impulse_y_n_s_m (the impulse
    of that space's jet on the robot over the run, N·s per metre of hub height: the sum of
    force × h over the steps), jetting_s (how long its force was nonzero: jetting, or with
    `jet_inflow` refilling; s).

    The force of a step is the engine's jet term for that step, recomputed in f64 by the NumPy
    twin (`reference.ReferenceSimulator.space_jets`) from the shapes before and after it: its
    area rate (S(q_{k+1}) − S(q_k))/h is the engine's when the run is implicit Euler with fixed
    steps and a record at every step (`record_interval_s` = dt, `record_shapes=True`). A failed
    instance's rows are NaN. ValueError for any other run, before any compute."""
    if result.shapes is None or result.topology is None:
        raise ValueError("jet_impulses needs recorded shapes of one topology: simulate with "
                         "record_interval_s = dt and record_shapes=True")
    solver = result.solver
    check_jet_solver(solver)
    times = np.sort(result.trajectory["t_s"].unique())
    spacing = np.diff(times)
    if len(times) < 2 or not np.allclose(spacing, solver.dt, rtol=ROUND_OFF, atol=0.0):
        raise ValueError(f"jet_impulses needs a record at every step (record_interval_s = dt = "
                         f"{solver.dt} s), got records {spacing.min() if len(spacing) else 0} "
                         f"to {spacing.max() if len(spacing) else 0} s apart")
    rows = []
    for instance, row in result.summary.iterrows():
        twin = ReferenceSimulator(StarParams.from_row(row))
        shapes = result.shapes[:, instance]
        if np.isfinite(shapes).all():
            # every step at once: forces (steps, 8, 2)
            force = twin.space_jets(shapes[1:], shapes[:-1], solver.dt)[0]
            impulse = (force * solver.dt).sum(axis=0)
            jetting = solver.dt * (np.abs(force).sum(axis=2) > 0.0).sum(axis=0)
        else:
            impulse, jetting = np.full((N_ACTUATORS, 2), np.nan), np.full(N_ACTUATORS, np.nan)
        for space in range(N_ACTUATORS):
            rows.append({"instance": instance, "space": space + 1,
                         "impulse_x_n_s_m": impulse[space, 0],
                         "impulse_y_n_s_m": impulse[space, 1], "jetting_s": jetting[space]})
    return pd.DataFrame(rows, columns=["instance", "space", "impulse_x_n_s_m", "impulse_y_n_s_m",
                                       "jetting_s"])
