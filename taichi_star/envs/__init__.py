"""Gymnasium environments of the star robot. Importing this module registers them:

- ``gymnasium.make("StarSwimmer-v0", **kwargs)``: one robot swimming to a goal point
  (`StarSwimmerEnv`);
- ``gymnasium.make_vec("StarSwimmer-v0", num_envs=64, **kwargs)``: 64 robots in one engine
  (`StarSwimmerVectorEnv`, the registered vector entry point);
- ``to_sb3(envs)``: that vector env as a Stable-Baselines3 VecEnv (`taichi_star.envs.sb3`;
  needs stable-baselines3, which taichi_star does not install);
- ``drive_policy(policy, goals)``: a policy (a trained agent) driven to given goals and judged
  at rest as the planners judge theirs (`taichi_star.envs.rollout`).

Both take ``render_mode="rgb_array"`` (a picture of the robot from `render()`).

Made by ``gymnasium.make`` or ``make_vec``, both stop an episode after
DEFAULT_MAX_EPISODE_STEPS (40) control periods unless given `max_episode_steps=N`; built
directly from their classes, neither has a budget unless given one. The keyword arguments,
spaces and reward are described in `taichi_star.envs.swimmer`.

Gymnasium comes with the ``envs`` extra (``pip install "taichi_star[envs]"``).
"""

from ..extras import require

gymnasium = require("gymnasium", "envs")

from .rollout import POLICY_COLUMNS, POLICY_CYCLE_COLUMNS, drive_policy
from .sb3 import SB3VectorAdapter, to_sb3
from .swimmer import (DEFAULT_MAX_EPISODE_STEPS, OBSERVATION_NAMES, RENDER_MODES,
                      GoalReachingBatch, StarSwimmerEnv, StarSwimmerVectorEnv, SwimmerTask,
                      control_period)

ENV_ID = "StarSwimmer-v0"
"""The id `gymnasium.make` and `gymnasium.make_vec` take (registered on import)."""

if ENV_ID not in gymnasium.registry:
    gymnasium.register(id=ENV_ID, entry_point="taichi_star.envs.swimmer:StarSwimmerEnv",
                       vector_entry_point="taichi_star.envs.swimmer:StarSwimmerVectorEnv",
                       max_episode_steps=DEFAULT_MAX_EPISODE_STEPS)

__all__ = ["DEFAULT_MAX_EPISODE_STEPS", "ENV_ID", "OBSERVATION_NAMES", "POLICY_COLUMNS",
           "POLICY_CYCLE_COLUMNS", "RENDER_MODES", "GoalReachingBatch", "SB3VectorAdapter",
           "StarSwimmerEnv", "StarSwimmerVectorEnv", "SwimmerTask", "control_period",
           "drive_policy", "to_sb3"]
