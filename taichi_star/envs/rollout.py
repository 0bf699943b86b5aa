"""A policy of the goal-reaching task driven to given goals and judged as the planners judge
theirs (`planner.drive`, `lookahead.lookahead_drive`), so that a trained agent's table sits
beside theirs (`lookahead.compare_controllers`).

Every robot sees what the environments show it (`GoalReachingBatch.observe`) and fires what
the policy answers, one control period (the actuation period) at a time, all robots in one
Simulator. A robot's controller stops when the task would end its episode: within the
tolerance at a period boundary (the environment's `terminated`, its success), its solver
failed, or after max_cycles; it then coasts, firing nothing, and is judged where it comes to
rest, `settle_cycles` periods after its stop, as the planners' robots are: an agent trained
to reach the tolerance in passing does not plan for the glide after it, and the table shows
both.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import pandas as pd

from ..gait import Gait
from ..params import SolverConfig, StarParams
from ..planner import PLAN_COLUMNS, SETTLE_CYCLES, check_drive, judged_at_rest
from .swimmer import GoalReachingBatch, SwimmerTask, observation_space

__all__ = ["drive_policy", "POLICY_COLUMNS", "POLICY_CYCLE_COLUMNS"]

POLICY_COLUMNS = [*PLAN_COLUMNS, "terminated"]
"""Columns of `drive_policy`'s summary: `planner.PLAN_COLUMNS` (reached: at rest within the
tolerance, settle_cycles after the stop) and terminated (within the tolerance at a period
boundary while driven, and as slow as the task asks: the environment's success)."""
POLICY_CYCLE_COLUMNS = ["goal", "mode", "cycle", "gait", "x_mm", "y_mm", "heading_deg",
                        "distance_mm"]
"""Columns of `drive_policy`'s per-cycle table: the robot's state at the start of cycle
`cycle` and the gait the policy fired there ("none" after its controller stopped)."""


def drive_policy(policy: Callable[[np.ndarray], np.ndarray], goals_mm,
                 params: StarParams = StarParams(), solver: SolverConfig = SolverConfig(),
                 tolerance_mm: float = 5.0, max_cycles: int = 25,
                 settle_cycles: int = SETTLE_CYCLES, frames_per_cycle: int = 10,
                 mode: str = "policy", stop_speed_mm_s=None, settled: bool = False,
                 since_fired_cap_s: float = SwimmerTask.since_fired_cap_s, arch: str = "cpu"):
    """Drive one robot per goal by `policy` (module docstring) and judge it at rest.

    policy: observations (G, 15) float32 (`swimmer.OBSERVATION_NAMES`) -> actions (G, 8) of 0
    and 1 (`MultiBinary(8)`; a Stable-Baselines3 model: ``lambda obs: model.predict(obs,
    deterministic=True)[0]``), asked once an actuation period for every robot (the answers of
    robots whose controller stopped are not fired): the environments' default control
    period; a policy trained at a shorter `control_period_s` is not asked at its own. goals_mm: (G, 2) mm from the start (the robot starts at
    rest, heading 0). mode: the summary's `mode` (a name for the policy). stop_speed_mm_s: the
    task's (`swimmer.SwimmerTask`): with it a controller stops within the tolerance only once
    its robot is that slow, as the environment it was trained in ends an episode. settled:
    the task's `settle_cycles` is settle_cycles (a controller stops within the tolerance only
    once its robot has fired nothing for settle_cycles periods), and a controller that stops
    so is deemed to have stopped settle_cycles periods before: it is judged where its episode
    ended, its `terminated` the same as its `reached` (an instance ok). since_fired_cap_s:
    the task's (the largest time since firing observed), that of the policy's training.
    Returns (summary `POLICY_COLUMNS`, cycles `POLICY_CYCLE_COLUMNS`, path (goal, mode, t_s,
    controlled, x_mm, y_mm) recorded frames_per_cycle times a period). ValueError before any
    compute for arguments `planner.drive` refuses, and naming the policy for an answer that
    is no action."""
    goals = check_drive(goals_mm, params, solver, tolerance_mm, max_cycles, frames_per_cycle,
                        settle_cycles)
    if not callable(policy):
        raise ValueError(f"policy must be a callable from observations to actions, got "
                         f"{type(policy).__name__}")
    if not isinstance(mode, str) or not mode:
        raise ValueError(f"mode must be a non-empty name, got {mode!r}")
    if not isinstance(settled, (bool, np.bool_)):
        raise ValueError(f"settled must be True or False, got {settled!r}")
    if settled and settle_cycles < 1:
        raise ValueError(f"settled needs settle_cycles >= 1 (the periods a robot coasts before "
                         f"its episode ends), got {settle_cycles!r}")
    count = len(goals)
    robots = np.arange(count)
    # a drawn goal is never asked for: the task's distance only has to exceed the tolerance
    task = SwimmerTask(goal_distance_mm=float(np.hypot(*goals.T).max()),
                       goal_tolerance_mm=tolerance_mm,
                       stop_speed_mm_s=stop_speed_mm_s,
                       settle_cycles=settle_cycles if settled else None,
                       since_fired_cap_s=since_fired_cap_s)
    batch = GoalReachingBatch(count, params, solver, None, task, arch)
    space = observation_space(task)
    batch.reset(robots, [], goals)
    period = batch.control_period_s
    interval = period / frames_per_cycle
    driving = np.ones(count, dtype=bool)
    terminated = np.zeros(count, dtype=bool)
    stop_cycle = np.full(count, max_cycles)
    final_error = np.full(count, np.nan)
    fired = np.zeros(count, dtype=np.int64)
    boundaries, cycle_rows, paths = [], [], []
    for cycle in range(max_cycles + settle_cycles + 1):
        observation, info = batch.observe(space)
        position, distance = info["position_mm"], np.hypot(*(goals - info["position_mm"]).T)
        boundaries.append(position)
        # the environment's episode end: arrived (within the tolerance, and slow enough where
        # the task asks it to stop), a failed solver, the budget
        arrived = batch.arrived()
        stopping = driving & (arrived | (info["status"] != "ok") | (cycle == max_cycles))
        terminated |= stopping & arrived
        # a settled episode's end: its controller is deemed to have stopped settle_cycles
        # periods before (it fired nothing since), so that it is judged where it ended
        stopped_at = (cycle - np.where(arrived & settled, settle_cycles, 0))[stopping]
        stop_cycle[stopping] = stopped_at
        final_error[stopping] = np.hypot(
            *(goals[stopping] - np.stack(boundaries)[stopped_at, robots[stopping]]).T)
        driving &= ~stopping
        actions = np.zeros((count, 8), dtype=bool)
        if driving.any():
            try:
                answer = policy(observation)
                actions = GoalReachingBatch.firing_mask(answer, (count, 8)) & driving[:, None]
            except ValueError as error:
                raise ValueError(f"policy: {error}") from None
        if (driving | stopping).any():  # the cycles while any robot is driven, and its stop
            cycle_rows.append(pd.DataFrame({
                "goal": robots, "mode": mode, "cycle": cycle,
                "gait": [Gait.from_mask(row).name for row in actions],
                "x_mm": position[:, 0], "y_mm": position[:, 1],
                "heading_deg": info["heading_deg"], "distance_mm": distance}))
        if not driving.any() and cycle >= stop_cycle.max() + settle_cycles:
            break  # every robot has come to rest, settle_cycles after its stop
        fired += actions.any(axis=1)
        frames = batch.swim(actions, record_interval_s=interval)
        paths.append(pd.DataFrame({
            "goal": frames["instance"].to_numpy(), "mode": mode,
            "t_s": frames["t_s"].to_numpy(), "x_mm": frames["centroid_x_mm"].to_numpy(),
            "y_mm": frames["centroid_y_mm"].to_numpy()}))
    summary = judged_at_rest(goals, robots, mode, boundaries, stop_cycle, settle_cycles,
                             batch.simulator.state()["status"].to_numpy(), tolerance_mm, fired,
                             final_error).assign(terminated=terminated)[POLICY_COLUMNS]
    start = pd.DataFrame({"goal": robots, "mode": mode, "t_s": 0.0, "x_mm": 0.0, "y_mm": 0.0})
    path = pd.concat([start, *paths], ignore_index=True)
    path["controlled"] = path["t_s"] <= (stop_cycle[path["goal"].to_numpy()] * period
                                         + solver.dt / 2)
    path = path.sort_values(["goal", "t_s"], kind="stable").reset_index(drop=True)
    batch.close()
    return (summary, pd.concat(cycle_rows, ignore_index=True)[POLICY_CYCLE_COLUMNS],
            path[["goal", "mode", "t_s", "controlled", "x_mm", "y_mm"]])
