"""Reach-a-goal environments for the star robot: `StarSwimmerEnv` (one robot, `gymnasium.Env`)
and `StarSwimmerVectorEnv` (num_envs robots advanced together in ONE `Simulator`, a
`gymnasium.vector.VectorEnv`). Both are built on `GoalReachingBatch`, so a robot behaves the
same (to the last bit) alone or as one instance of the vector env.

Task. A robot starts at rest at the origin with heading 0; a goal point is drawn at
`goal_distance_mm` in a uniformly random direction from the environment's seeded generator
(or given by `reset(options={"goal": (x_mm, y_mm)})`).

Action: `MultiBinary(8)`, column m = actuator A(m+1): the actuators fired at the start of the
control period (`control_period_s`, default one actuation period of the StarParams). Then the
robot swims for the whole period without further commands.

Observation (`Box` float32, `OBSERVATION_NAMES`): the goal relative to the robot's centroid in
the body frame (mm; the body frame is the world frame turned by the heading, x along the rest
direction of A1's bisector); sin and cos of the heading; the centroid's velocity in the body
frame (mm/s) and the angular velocity (deg/s); the time since each actuator last fired (s),
capped at `since_fired_cap_s`, which is also what a never-fired actuator reads. Values beyond
the space's bounds (a robot 10 m from its goal) are clipped to them.

Reward per step: progress toward the goal (mm: distance before the step minus distance after)
minus `firing_cost_mm` per actuator fired. Terminated when the centroid is within
`goal_tolerance_mm` of the goal (with `stop_speed_mm_s`, and its speed at most that: the robot
must arrive and stop, not swim through; with `settle_cycles`, and only once it has fired nothing
for that many periods: it must have coasted to the goal, as the planners judge a robot where it
is that long after its controller stopped); truncated after `max_episode_steps` steps (the last one
truncated even when it reached the goal, as gymnasium's TimeLimit), or when the instance's
solver failed short of its goal (its robot is frozen; `info["status"]` says why). Made through
`gymnasium.make`, the single env gets its step budget as gymnasium's TimeLimit wrapper
(`DEFAULT_MAX_EPISODE_STEPS` unless `gymnasium.make(..., max_episode_steps=N)`), and
`gymnasium.make_vec` hands the same budget to the vector env; built directly, either env has
no budget unless given `max_episode_steps`.

The vector env autoresets in gymnasium's NEXT_STEP mode: the step after an episode ends
resets that robot, ignores its action and returns its first observation with reward 0 (and
terminated = truncated = False). `reset(seed=s)` seeds robot b with s + b, as
`gymnasium.vector.SyncVectorEnv` does, so robot b of the vector env reproduces
`StarSwimmerEnv` reset with seed s + b.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Mapping, Optional, Sequence

import gymnasium as gym
import numpy as np
import pandas as pd
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ..checks import is_finite_real, is_whole, shown
from ..extras import require
from ..gait import N_ACTUATORS
from .. import drawing, metrics
from ..metrics import MAX_GOAL_MM, rotate
from ..params import SolverConfig, StarParams
from ..simulator import ACTUATOR_COLUMNS, NotCopied, Simulator
from ..timegrid import check_work, steps_in, whole_steps

# the public names (docs/api.md documents these; the rest are the environments' parts)
__all__ = ["StarSwimmerEnv", "StarSwimmerVectorEnv", "SwimmerTask", "GoalReachingBatch",
           "control_period", "OBSERVATION_NAMES", "DEFAULT_MAX_EPISODE_STEPS", "RENDER_MODES"]

OBSERVATION_NAMES = ("goal_x_body_mm", "goal_y_body_mm", "heading_sin", "heading_cos",
                     "velocity_x_body_mm_s", "velocity_y_body_mm_s", "angular_velocity_deg_s",
                     *ACTUATOR_COLUMNS)
"""The observation's entries, in order."""

GOAL_BOUND_MM = 1e4
"""Bound of the body-frame goal entries, mm (10 m: ~100 robot diameters)."""
VELOCITY_BOUND_MM_S = 1e3
"""Bound of the velocity entries, mm/s (the robot swims at < 10 mm/s, its limbs at < 100)."""
ANGULAR_VELOCITY_BOUND_DEG_S = 1e4
"""Bound of the angular velocity entry, deg/s."""
DEFAULT_MAX_EPISODE_STEPS = 40
"""The registered step budget (control periods) of StarSwimmer-v0."""
RENDER_MODES = ("rgb_array",)
"""`render_mode`s the environments offer: "rgb_array" (a picture of the robot, its heating
actuators and its goal, drawn with matplotlib's Agg backend; no window)."""


@dataclass(frozen=True)
class SwimmerTask:
    """The goal-reaching task's settings (validated; ValueError names the field).

    goal_distance_mm: distance of a randomly drawn goal from the start, mm, (0, 1000], more
    than goal_tolerance_mm (a goal within it would start reached);
    goal_tolerance_mm: the episode terminates within this distance of the goal, mm, (0, 1000];
    firing_cost_mm: reward subtracted per fired actuator, mm of progress, [0, 1000];
    max_episode_steps: control periods before truncation, >= 1, or None (no budget);
    since_fired_cap_s: the largest time-since-fired observed (and that of a never-fired
    actuator), s, (0, 1e6];
    stop_speed_mm_s: None (the episode ends within the tolerance, however fast the robot
    swims through it) or the centroid speed, mm/s, (0, 1000], at or below which the robot must
    be too (it must stop there: the judgement of the planners, who judge a goal at rest);
    settle_cycles: None, or the control periods, >= 1 (and below max_episode_steps), the robot
    must have fired nothing when it is within the tolerance for its episode to end there (it
    must have coasted there: the planners judge a robot where it is settle_cycles periods after
    its controller stopped firing, its glide under quadratic drag lasting that long). Checked
    against the budget where the environment holds it (built with max_episode_steps, or by
    `gymnasium.make_vec`, which hands it over); `gymnasium.make` keeps the budget in its
    TimeLimit wrapper, which the environment never sees, so there keep settle_cycles below it
    (DEFAULT_MAX_EPISODE_STEPS unless given): at or above it no episode ends at its goal."""

    goal_distance_mm: float = 50.0
    goal_tolerance_mm: float = 5.0
    firing_cost_mm: float = 0.1
    max_episode_steps: Optional[int] = None
    since_fired_cap_s: float = 10.0
    stop_speed_mm_s: Optional[float] = None
    settle_cycles: Optional[int] = None

    def __post_init__(self):
        for name, lowest, highest, lowest_allowed in (
                ("goal_distance_mm", 0.0, MAX_GOAL_MM, False),
                ("goal_tolerance_mm", 0.0, MAX_GOAL_MM, False),
                ("firing_cost_mm", 0.0, MAX_GOAL_MM, True),
                ("since_fired_cap_s", 0.0, 1e6, False)):
            value = getattr(self, name)
            if not is_finite_real(value) or value > highest or value < lowest \
                    or (value == lowest and not lowest_allowed):
                bracket = "[" if lowest_allowed else "("
                raise ValueError(f"{name} must be a number in {bracket}{lowest:g}, {highest:g}], "
                                 f"got {shown(value)}")
            object.__setattr__(self, name, float(value))
        if self.goal_distance_mm <= self.goal_tolerance_mm:
            # every drawn goal would start reached: each episode over at its first step,
            # whatever the agent does (an audit, 2026-12)
            raise ValueError(f"goal_distance_mm must exceed goal_tolerance_mm "
                             f"({self.goal_tolerance_mm!r} mm), got {self.goal_distance_mm!r}")
        speed = self.stop_speed_mm_s
        if speed is not None:
            if not is_finite_real(speed) or not 0.0 < speed <= VELOCITY_BOUND_MM_S:
                raise ValueError(f"stop_speed_mm_s must be None or a number in (0, "
                                 f"{VELOCITY_BOUND_MM_S:g}] mm/s, got {shown(speed)}")
            object.__setattr__(self, "stop_speed_mm_s", float(speed))
        steps = self.max_episode_steps
        if steps is not None:
            if not is_whole(steps) or steps < 1:
                raise ValueError(f"max_episode_steps must be an integer >= 1 or None, got "
                                 f"{steps!r}")
            object.__setattr__(self, "max_episode_steps", int(steps))
        settle = self.settle_cycles
        if settle is not None:
            if not is_whole(settle) or settle < 1:
                raise ValueError(f"settle_cycles must be an integer >= 1 or None, got "
                                 f"{settle!r}")
            if steps is not None and settle >= steps:
                # no episode could end at its goal: it needs a period to fire in
                raise ValueError(f"settle_cycles must be below max_episode_steps ({steps}), "
                                 f"got {settle!r}")
            object.__setattr__(self, "settle_cycles", int(settle))


def observation_space(task: SwimmerTask) -> spaces.Box:
    """The Box of one robot's observation (`OBSERVATION_NAMES`), float32."""
    high = np.array([GOAL_BOUND_MM, GOAL_BOUND_MM, 1.0, 1.0, VELOCITY_BOUND_MM_S,
                     VELOCITY_BOUND_MM_S, ANGULAR_VELOCITY_BOUND_DEG_S,
                     *[task.since_fired_cap_s] * N_ACTUATORS], dtype=np.float32)
    low = -high
    low[-N_ACTUATORS:] = 0.0
    return spaces.Box(low=low, high=high, dtype=np.float32)


def checked_seed(seed, name: str = "seed"):
    """`seed` if it is None or an int >= 0 (what gymnasium's generators take), as a Python int;
    else ValueError naming it, before anything is reset."""
    if seed is None:
        return None
    if not is_whole(seed) or seed < 0:
        raise ValueError(f"{name} must be None or an integer >= 0, got {seed!r}")
    return int(seed)


def checked_options(options, allowed: Sequence[str]) -> dict:
    """A copy of `reset`'s options: None gives {}; ValueError naming the options for anything
    but a dict, or naming the keys outside `allowed` (a misspelt "gaol" would otherwise be
    ignored silently)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise ValueError(f"options must be a dict with keys {sorted(allowed)} or None, got "
                         f"{type(options).__name__} {options!r}")
    unknown = sorted(str(key) for key in options if key not in allowed)
    if unknown:
        raise ValueError(f"options has unknown keys {unknown}; the allowed keys are "
                         f"{sorted(allowed)}")
    return dict(options)


def goal_from_options(options, count: int) -> Optional[np.ndarray]:
    """(count, 2) goals (mm) from `options["goal"]` ((2,) for every robot or (count, 2)), or
    None without one. ValueError naming "goal" for a bad shape, a non-finite value or a goal
    further than MAX_GOAL_MM."""
    if options is None or "goal" not in options:
        return None
    try:
        goal = np.asarray(options["goal"], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"options['goal'] must be (x_mm, y_mm) numbers, got "
                         f"{options['goal']!r}") from None
    if goal.shape == (2,):
        goal = np.tile(goal, (count, 1))
    if goal.shape != (count, 2):
        raise ValueError(f"options['goal'] must have shape (2,) or ({count}, 2), got "
                         f"{goal.shape}")
    if not np.isfinite(goal).all():
        raise ValueError(f"options['goal'] must be finite, got {options['goal']!r}")
    if (np.hypot(goal[:, 0], goal[:, 1]) > MAX_GOAL_MM).any():
        raise ValueError(f"options['goal'] must be within {MAX_GOAL_MM:g} mm of the start, got "
                         f"{options['goal']!r}")
    return goal


def control_period(params: StarParams, solver: SolverConfig,
                   control_period_s: Optional[float] = None) -> float:
    """The control period, s: control_period_s, or the actuation period of `params` when None;
    ValueError unless it is a positive whole number of solver steps, at most the steps a run
    may take (`timegrid.check_work`: a period of 1e7 s was refused only at the first step,
    naming duration_s). No compute: a command line checks its input with this before building
    an environment."""
    period = params.period if control_period_s is None else control_period_s
    if not is_finite_real(period) or period <= 0 \
            or whole_steps(period, solver.dt) is None:
        raise ValueError(f"control_period_s must be a positive whole number of steps "
                         f"(dt = {solver.dt} s), got {control_period_s!r}")
    check_work(f"control_period_s = {period:g} s at dt = {solver.dt:g} s",
               steps_in(period, solver.dt))
    return float(period)


class GoalReachingBatch:
    """The task on B robots of one Simulator: goals, observations, rewards, episode ends.

    params: one StarParams (every robot) or B of them sharing a topology (their gait is
    ignored); solver: SolverConfig; control_period_s: s, a whole number of solver steps
    (default the first robot's actuation period); task: SwimmerTask."""

    def __init__(self, n_robots: int, params=None, solver: Optional[SolverConfig] = None,
                 control_period_s: Optional[float] = None, task: SwimmerTask = SwimmerTask(),
                 arch: str = "cpu"):
        if not is_whole(n_robots) or n_robots < 1:
            raise ValueError(f"num_envs must be an integer >= 1, got {n_robots!r}")
        params = StarParams.preset("paper") if params is None else params
        if isinstance(params, StarParams):
            params = [params] * n_robots
        if not all(isinstance(p, StarParams) for p in params):
            raise ValueError(f"params must be a StarParams or a sequence of {n_robots}")
        params = [p.replace(gait="none") for p in params]
        if len(params) != n_robots:
            raise ValueError(f"params must be one StarParams or {n_robots}, got {len(params)}")
        solver = SolverConfig.preset("paper") if solver is None else solver
        if not isinstance(solver, SolverConfig):  # read (its dt) before the Simulator checks it
            raise ValueError(f"solver must be a SolverConfig, got {type(solver).__name__}")
        if not isinstance(task, SwimmerTask):
            raise ValueError(f"task must be a SwimmerTask, got {type(task).__name__}")
        period = control_period(params[0], solver, control_period_s)
        self.task = task
        self.params = params
        self.control_period_s = period
        self._simulator = Simulator(params, solver, arch=arch)
        self.n_robots = n_robots
        self.goals = np.zeros((n_robots, 2))
        self.distances = np.zeros(n_robots)
        self.speeds = np.zeros(n_robots)
        """Each robot's centroid speed at the last control period's end, mm/s."""
        self.episode_steps = np.zeros(n_robots, dtype=np.int64)
        self.coasted = np.zeros(n_robots, dtype=np.int64)
        """Control periods since each robot last fired (in this episode), at the last end."""
        self.started = np.zeros(n_robots, dtype=bool)
        """Whether each robot has had its first reset (a goal to swim to)."""

    @property
    def simulator(self) -> Simulator:
        """The robots' Simulator; RuntimeError once the batch is closed."""
        if self._simulator is None:
            raise RuntimeError("this environment is closed; make a new one to go on")
        return self._simulator

    def check_open(self):
        """RuntimeError once the batch is closed (as `simulator`)."""
        self.simulator

    def close(self):
        """Let go of the Simulator: once nothing else refers to it, its engine (compiled
        kernels, device memory) is free in the process's runtime, which gives it to the next
        Simulator of the same topology, terms and integrator instead of compiling another.
        Closing again does nothing."""
        self._simulator = None

    def reset(self, rows: np.ndarray, generators: Sequence[np.random.Generator],
              goals: Optional[np.ndarray] = None):
        """Put robots `rows` back at the start with new goals: `goals` (len(rows), 2) mm, or
        one drawn per robot from its generator (uniform direction, the task's distance)."""
        rows = np.asarray(rows, dtype=np.int64)
        if goals is None:
            angles = np.array([generator.uniform(-math.pi, math.pi) for generator in generators])
            goals = self.task.goal_distance_mm * np.stack([np.cos(angles), np.sin(angles)], 1)
        self.simulator.reset(rows)
        self.goals[rows] = goals
        self.distances[rows] = np.hypot(goals[:, 0], goals[:, 1])
        self.speeds[rows] = 0.0  # at rest at the start
        self.episode_steps[rows] = 0
        self.coasted[rows] = 0
        self.started[rows] = True

    @staticmethod
    def firing_mask(actions, shape) -> np.ndarray:
        """Bool mask of `actions`: exactly `shape`, of any type `MultiBinary` accepts (boolean,
        or integers or floats that are exactly 0 or 1: RL libraries emit float32 0./1.);
        ValueError naming the action otherwise (0.5, 2, NaN, text, None, ragged lists: these
        were a TypeError or NumPy's own words, and a list of Python objects 0 and 1, which the
        space holds, was refused; an audit, 2026-12)."""
        try:
            array = np.asarray(actions)
        except (TypeError, ValueError):  # ragged: [0, [1, 2]]
            raise ValueError(f"action must be an array of shape {shape} of 0 and 1, got a "
                             f"ragged {type(actions).__name__}") from None
        if array.shape != shape:
            raise ValueError(f"action must have shape {shape} (one 0/1 per actuator A1..A8), "
                             f"got {array.shape}")
        if array.dtype == bool:
            return array.copy()
        numbers = array
        if array.dtype.kind == "O":  # Python objects, as MultiBinary.contains takes them
            try:
                numbers = array.astype(float)
            except (TypeError, ValueError):
                numbers = None
        if numbers is not None and numbers.dtype.kind in "iuf":
            binary = np.isin(numbers, (0, 1))
            if binary.all():
                return numbers.astype(bool)
            wrong = array[~binary].ravel()
        else:
            wrong = array.ravel()
        raise ValueError(f"action must hold only 0 and 1 (boolean, integer or float), got "
                         f"dtype {array.dtype} with values {wrong[:4].tolist()}")

    def swim(self, fire: np.ndarray, record_interval_s: float = 0.0) -> pd.DataFrame:
        """Fire `fire` ((B, 8) bool) now and advance one control period; the distances to the
        goals and the episodes' steps follow. Returns the Simulator's records every
        `record_interval_s` (none at 0). RuntimeError for a robot never reset: it has no goal
        yet (a vector env stepped before reset ended every episode at once, at the goal (0, 0)
        it starts on; gymnasium's wrappers enforce the order, a bare env did not)."""
        simulator = self.simulator  # a closed environment says so first (an audit, 2026-12)
        if not self.started.all():
            raise RuntimeError(f"call reset() before step(): robot "
                               f"{np.flatnonzero(~self.started)[0]} has no episode yet")
        simulator.fire(fire)
        # no progress bar for a control period, however many robots: an agent steps many
        frames = simulator.advance(self.control_period_s, record_interval_s=record_interval_s,
                                   progress=False)
        state = simulator.state()
        position = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
        self.distances = np.hypot(*(self.goals - position).T)
        self.speeds = np.hypot(*state[["velocity_x_mm_s", "velocity_y_mm_s"]].to_numpy().T)
        self.episode_steps += 1
        self.coasted = np.where(fire.any(axis=1), 0, self.coasted + 1)
        return frames

    def arrived(self) -> np.ndarray:
        """(B,) bool: within the task's tolerance of the goal now, with `stop_speed_mm_s` at
        most that fast, with `settle_cycles` having fired nothing for at least that many periods
        (the task's success, which ends an episode)."""
        arrived = self.distances <= self.task.goal_tolerance_mm
        if self.task.stop_speed_mm_s is not None:
            arrived &= self.speeds <= self.task.stop_speed_mm_s
        if self.task.settle_cycles is not None:
            arrived &= self.coasted >= self.task.settle_cycles
        return arrived

    def step(self, fire: np.ndarray):
        """`swim` one control period, judged as the task does. Returns rewards (B,) float64,
        terminated (B,), truncated (B,)."""
        # a failed robot fires nothing (the Simulator ignores its commands), so pays nothing
        # (it paid for firings that never happened: an audit, 2026-12)
        fired = fire & self.simulator.ok[:, None]
        before = self.distances.copy()
        self.swim(fire)
        rewards = before - self.distances - self.task.firing_cost_mm * fired.sum(axis=1)
        terminated = self.arrived()
        out_of_steps = (self.episode_steps >= self.task.max_episode_steps
                        if self.task.max_episode_steps is not None else False)
        # as gymnasium's TimeLimit: the step budget's last step is truncated whether or not
        # the goal was reached on it (a reached goal was not truncated here, so `make_vec` and
        # a SyncVectorEnv of `make`'s envs differed; an audit, 2026-12); a failed solver
        # truncates an episode that did not end at its goal
        truncated = out_of_steps | (~terminated & ~self.simulator.ok)
        return rewards, terminated, truncated

    def observe(self, space: spaces.Box):
        """(B, 15) float32 observations (clipped to `space`) and the info dict of arrays:
        position_mm (B, 2), goal_mm (B, 2), heading_deg, distance_mm, time_s, status,
        newton_capped (`Simulator.state()`'s)."""
        state = self.simulator.state()
        heading = np.radians(state["heading_deg"].to_numpy())
        position = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
        velocity = state[["velocity_x_mm_s", "velocity_y_mm_s"]].to_numpy()
        since = state[list(ACTUATOR_COLUMNS)].to_numpy()
        since = np.where(np.isnan(since), self.task.since_fired_cap_s, since)
        columns = np.column_stack([
            rotate(self.goals - position, -heading), np.sin(heading), np.cos(heading),
            rotate(velocity, -heading), state["angular_velocity_deg_s"].to_numpy(), since])
        # a failed (frozen) robot may hold non-finite values; the observation must stay in space
        columns = np.nan_to_num(columns, nan=0.0)
        observation = np.clip(columns, space.low, space.high).astype(np.float32)
        info = {"position_mm": position, "goal_mm": self.goals.copy(),
                "heading_deg": state["heading_deg"].to_numpy(),
                "distance_mm": self.distances.copy(), "time_s": state["t_s"].to_numpy(),
                "status": state["status"].to_numpy(),
                "newton_capped": state["newton_capped"].to_numpy()}
        return observation, info


    def pictures(self, rows) -> list:
        """An (400, 400, 3) uint8 RGB picture of each robot of `rows` (see
        `taichi_star.drawing.robot_image`): its shape, the actuators heating now in red, the
        goal (a green star), in the frame of the task (mm from the robot's start)."""
        state = self.simulator.state()
        shapes_mm = self.simulator.shapes() * metrics.METERS_TO_MM
        # the task's frame has its origin at the start centroid: shift each robot by the
        # difference between its centroid now and its centroid relative to the start
        absolute = metrics.centroid(shapes_mm, self.simulator.model.mass)
        relative = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()
        since = state[list(ACTUATOR_COLUMNS)].to_numpy()
        pictures = []
        for row in rows:
            params = self.params[row]
            pictures.append(drawing.robot_image(
                shapes_mm[row] - absolute[row] + relative[row], self.simulator.model.topology,
                drawing.hot_actuators(since[row], params.actuator_profile.switch_time,
                                      params.actuator_delays),
                params.cylinder_diameter * metrics.METERS_TO_MM, goal_mm=self.goals[row],
                title=f"t = {state['t_s'].iloc[row]:.2f} s, {self.distances[row]:.1f} mm to go"))
        return pictures


def checked_render_mode(render_mode):
    """render_mode, which must be None or "rgb_array" (ValueError naming it otherwise); the
    pictures need matplotlib: an ImportError naming the extra when it is missing, now, not at
    the first `render()` after the run (SB3's `make_vec_env` asks for "rgb_array" by default:
    an audit)."""
    if render_mode not in RENDER_MODES + (None,):
        raise ValueError(f"render_mode must be None or one of {list(RENDER_MODES)}, got "
                         f"{render_mode!r}")
    if render_mode == "rgb_array":
        require("matplotlib", "plots")
    return render_mode


def checked_task(task: dict) -> "SwimmerTask":
    """The SwimmerTask of an environment's task keywords; ValueError naming an unknown one and
    the keywords there are (a TypeError of the dataclass before)."""
    known = [field.name for field in dataclasses.fields(SwimmerTask)]
    unknown = [name for name in task if name not in known]
    if unknown:
        raise ValueError(f"unknown keyword {unknown[0]!r}: an environment takes params, solver, "
                         f"control_period_s, arch, render_mode and the task's {known}")
    return SwimmerTask(**task)


ENV_NOT_COPIED = ("an environment is not copied or pickled (its robots live in one "
                  "Simulator's engine): make another one, or save() env.simulator's state and "
                  "load() it into the other's simulator")
"""The TypeError of copying, deep-copying or pickling an environment."""


class RobotsView(NotCopied):
    """What both environments show of their robots: the Simulator and the control period
    (their `batch`, a `GoalReachingBatch`, holds them). Not copied or pickled (`NotCopied`)."""

    batch: GoalReachingBatch
    not_copied = ENV_NOT_COPIED

    @property
    def simulator(self) -> Simulator:
        """The `Simulator` that holds the robots (read its `state()`, `n_nodes` or shapes;
        stepping it directly bypasses the episodes). RuntimeError once the environment is
        closed."""
        return self.batch.simulator

    @property
    def control_period_s(self) -> float:
        """The simulated seconds one `step` advances, s."""
        return self.batch.control_period_s


class StarSwimmerEnv(RobotsView, gym.Env):
    """One star robot swimming to a goal point (see the module docstring for the spaces,
    reward and episode ends). Keyword arguments: params (a StarParams; default the paper
    preset), solver (SolverConfig; default the paper preset), control_period_s, arch, and the
    SwimmerTask fields (goal_distance_mm=50, goal_tolerance_mm=5, firing_cost_mm=0.1,
    max_episode_steps=None, since_fired_cap_s=10, stop_speed_mm_s=None, settle_cycles=None),
    and render_mode (None or "rgb_array": `render()` then returns a (400, 400, 3) uint8
    picture)."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 4}

    def __init__(self, params: Optional[StarParams] = None,
                 solver: Optional[SolverConfig] = None,
                 control_period_s: Optional[float] = None, arch: str = "cpu",
                 render_mode: Optional[str] = None, **task):
        if params is not None and not isinstance(params, StarParams):
            raise ValueError(f"params must be a StarParams, got {type(params).__name__}")
        self.render_mode = checked_render_mode(render_mode)
        self.batch = GoalReachingBatch(1, params, solver, control_period_s, checked_task(task),
                                       arch)
        self.observation_space = observation_space(self.batch.task)
        self.action_space = spaces.MultiBinary(N_ACTUATORS)

    def _observe(self):
        observation, info = self.batch.observe(self.observation_space)
        return observation[0], {key: value[0] for key, value in info.items()}

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        options = checked_options(options, ("goal",))
        # every argument checked before the generator is replaced: a bad one changes nothing
        seed, goal = checked_seed(seed), goal_from_options(options, 1)
        super().reset(seed=seed)
        self.batch.reset([0], [self.np_random], goal)
        return self._observe()

    def step(self, action):
        fire = self.batch.firing_mask(action, (N_ACTUATORS,))[None]
        rewards, terminated, truncated = self.batch.step(fire)
        observation, info = self._observe()
        return observation, float(rewards[0]), bool(terminated[0]), bool(truncated[0]), info

    def render(self):
        """With render_mode "rgb_array": the robot now as a (400, 400, 3) uint8 array (see
        `GoalReachingBatch.pictures`); None without a render mode. RuntimeError once closed."""
        self.batch.check_open()  # whatever the render mode
        return self.batch.pictures([0])[0] if self.render_mode == "rgb_array" else None

    def close(self):
        """Release the robot's engine for the next environment made in this process
        (`GoalReachingBatch.close`); a closed environment raises RuntimeError when stepped,
        reset or rendered."""
        self.batch.close()


class StarSwimmerVectorEnv(RobotsView, VectorEnv):
    """num_envs star robots in one Simulator, each with its own goal and episode (NEXT_STEP
    autoreset; see the module docstring). Keyword arguments as `StarSwimmerEnv`, except that
    params may also be a sequence of num_envs StarParams sharing a topology; with render_mode
    "rgb_array", `render()` returns a tuple of num_envs pictures."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 4,
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int = 1, params=None, solver: Optional[SolverConfig] = None,
                 control_period_s: Optional[float] = None, arch: str = "cpu",
                 render_mode: Optional[str] = None, **task):
        self.render_mode = checked_render_mode(render_mode)
        self.batch = GoalReachingBatch(num_envs, params, solver, control_period_s,
                                       checked_task(task), arch)
        self.num_envs = num_envs
        self.single_observation_space = observation_space(self.batch.task)
        self.single_action_space = spaces.MultiBinary(N_ACTUATORS)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._generators = [seeding.np_random(None)[0] for _ in range(num_envs)]
        self._autoreset = np.zeros(num_envs, dtype=bool)

    def reset(self, *, seed=None, options: Optional[dict] = None):
        """Reset every robot, or those of `options["reset_mask"]` ((num_envs,) bool). seed:
        None, an int s (robot b gets s + b) or a list of num_envs ints/None. options["goal"]:
        (2,) for every reset robot or (num_envs, 2) mm."""
        options = checked_options(options, ("goal", "reset_mask"))
        mask = np.ones(self.num_envs, dtype=bool)
        if "reset_mask" in options:
            mask = np.asarray(options.pop("reset_mask"))
            if mask.shape != (self.num_envs,) or mask.dtype != bool:
                raise ValueError(f"options['reset_mask'] must be a ({self.num_envs},) bool "
                                 f"array, got {mask.dtype} {mask.shape}")
        # every seed checked before any generator is replaced: a bad one changes nothing
        if seed is None:
            seeds = [None] * self.num_envs
        elif is_whole(seed):
            seeds = [checked_seed(seed) + b for b in range(self.num_envs)]
        elif (isinstance(seed, (list, tuple))
              or (isinstance(seed, np.ndarray) and seed.ndim == 1)) and len(seed) == self.num_envs:
            # a NumPy array of seeds too, as gymnasium's own vector envs take (an audit)
            seeds = [checked_seed(value, f"seed[{b}]") for b, value in enumerate(seed)]
        else:
            raise ValueError(f"seed must be None, an int or a list of {self.num_envs} seeds, "
                             f"got {seed!r}")
        goals = goal_from_options(options, self.num_envs)
        # the vector env's own generator takes a Python int seed only (a NumPy one raised
        # gymnasium's error, not ValueError; an audit); the robots' are set below
        super().reset(seed=seeds[0] if is_whole(seed) else None)
        rows = np.flatnonzero(mask)
        for b in rows:
            if seeds[b] is not None:  # as Env.reset: no seed keeps the robot's generator going
                self._generators[b] = seeding.np_random(seeds[b])[0]
        self.batch.reset(rows, [self._generators[b] for b in rows],
                         None if goals is None else goals[rows])
        self._autoreset[rows] = False
        return self._observe(mask)

    def _observe(self, reset=None):
        """Observations and info of every robot; `reset`: the (num_envs,) mask of the robots a
        partial reset reset, those whose info is given (SyncVectorEnv's convention: the info
        masks marked every robot after a partial reset; an audit, 2026-12)."""
        observation, info = self.batch.observe(self.single_observation_space)
        # gymnasium's vector info convention: every key has a "_key" mask of the robots it holds
        given = np.ones(self.num_envs, dtype=bool) if reset is None else reset.copy()
        info.update({f"_{key}": given.copy() for key in list(info)})
        return observation, info

    def step(self, actions):
        fire = self.batch.firing_mask(actions, (self.num_envs, N_ACTUATORS))
        restarting = np.flatnonzero(self._autoreset)
        fire[restarting] = False
        if len(restarting):
            # they swim this period with the others (one batch), from rest unfired rather than
            # from their finished episode's end (a failed or wild state's warnings came from a
            # robot in no episode; an audit, 2026-12); their goals are drawn below
            self.batch.simulator.reset(restarting)
        rewards, terminated, truncated = self.batch.step(fire)
        if len(restarting):
            # putting them back at the start afterwards gives exactly the first observation of
            # a new episode
            self.batch.reset(restarting, [self._generators[b] for b in restarting])
            rewards[restarting] = 0.0
            terminated[restarting] = False
            truncated[restarting] = False
        self._autoreset = terminated | truncated
        observation, info = self._observe()
        return observation, rewards, terminated, truncated, info

    def render(self):
        """With render_mode "rgb_array": a tuple of num_envs (400, 400, 3) uint8 pictures (see
        `GoalReachingBatch.pictures`); None without a render mode. RuntimeError once closed."""
        self.batch.check_open()  # whatever the render mode
        if self.render_mode != "rgb_array":
            return None
        return tuple(self.batch.pictures(range(self.num_envs)))

    def close_extras(self, **kwargs):
        """`close()`: release the robots' engine for the next environment made in this process
        (`GoalReachingBatch.close`); a closed environment raises RuntimeError when stepped,
        reset or rendered."""
        self.batch.close()
