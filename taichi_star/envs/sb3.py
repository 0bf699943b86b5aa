"""Stable-Baselines3 on the native vector environment.

SB3 takes its own `VecEnv` class, not a Gymnasium `VectorEnv` (given one, it answers "not a
Gymnasium environment"). `to_sb3(envs)` wraps a `StarSwimmerVectorEnv` in SB3's interface:

    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecMonitor
    from taichi_star.envs import StarSwimmerVectorEnv, to_sb3

    envs = VecMonitor(to_sb3(StarSwimmerVectorEnv(64, max_episode_steps=40)))
    PPO("MlpPolicy", envs, n_steps=16, batch_size=256).learn(10_000)

What the adapter does, as SB3's own `DummyVecEnv` does for single environments:
- actions: SB3's float32 0./1. samples of `MultiBinary(8)` are passed on (the environment takes
  any 0/1 numbers and still refuses 0.5 or 2);
- same-step autoreset: a robot whose episode ended in a step is reset within that step; the
  returned observation is its new episode's first, its info holds the final observation as
  `terminal_observation` and `TimeLimit.truncated` (truncated and not terminated);
- rewards float32 (num_envs,), dones bool (num_envs,) = terminated | truncated, infos a list of
  num_envs dicts (the vector env's info arrays, row by row);
- `seed(s)` seeds robot b with s + b at the next `reset()`, `set_options(...)` gives the next
  reset's options (one dict for every robot, or a list of num_envs dicts: equal ones, or each
  with its own `goal`), both used once, as in SB3;
- `get_attr` / `set_attr` / `env_method` act on the one vector environment (every index sees
  the same attribute; a method is called once and its result listed for each index);
  `env_is_wrapped` is False (the robots are not separate gymnasium.Env objects);
- `get_images()`: with render_mode "rgb_array", one picture per robot (SB3's `render()` tiles
  them).

Episode statistics for SB3's logger come from `VecMonitor`, as for any VecEnv.

SB3 is not a dependency of taichi_star: this module imports it only inside `to_sb3`, and the
class `SB3VectorAdapter` (the method set, without SB3's base class) works without it.
"""

from __future__ import annotations

import functools
import numbers
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from ..checks import is_whole
from .swimmer import StarSwimmerVectorEnv


def _same_options(first: Dict[str, Any], other: Dict[str, Any]) -> bool:
    """Whether two options dicts hold the same keys and values, arrays compared element by
    element (`!=` of two dicts holding arrays raised NumPy's "truth value of an array is
    ambiguous"; an audit, 2026-12)."""
    return first.keys() == other.keys() and all(
        np.array_equal(np.asarray(first[key], dtype=object), np.asarray(other[key], dtype=object))
        for key in first)


def _native_options(per_robot: List[Dict[str, Any]]) -> Dict[str, Any]:
    """The native vector env's one options dict from SB3's list of one per robot: equal dicts
    as they are; dicts of a goal each ((2,) mm) as options["goal"] (num_envs, 2). ValueError
    otherwise."""
    first = per_robot[0]
    if all(_same_options(first, other) for other in per_robot[1:]):
        return first
    if all(options.keys() == {"goal"} for options in per_robot):
        goals = [np.asarray(options["goal"]) for options in per_robot]
        if all(goal.shape == (2,) for goal in goals):
            return {"goal": np.stack(goals)}
    raise ValueError("set_options: the robots' options may differ only in their goals "
                     "({'goal': (x_mm, y_mm)} each); the native vector env takes one options "
                     "dict for every robot, per-robot goals as options['goal'] (num_envs, 2)")


def _rows_of(info: Dict[str, np.ndarray], count: int) -> List[Dict[str, Any]]:
    """The vector env's info dict of arrays as `count` dicts (the "_key" masks left out)."""
    return [{key: value[row] for key, value in info.items() if not key.startswith("_")}
            for row in range(count)]


# the public names (docs/api.md)
__all__ = ["to_sb3", "SB3VectorAdapter"]

class SB3VectorAdapter:
    """SB3's VecEnv interface over a `StarSwimmerVectorEnv` (see the module docstring).
    `to_sb3` makes one that is also an instance of SB3's `VecEnv` class, which SB3's algorithms
    require."""

    def __init__(self, envs: StarSwimmerVectorEnv):
        native = getattr(envs, "unwrapped", envs)
        if not isinstance(native, StarSwimmerVectorEnv):
            raise ValueError(f"envs must be a StarSwimmerVectorEnv (gymnasium.make_vec("
                             f"'StarSwimmer-v0', ...)), got {type(envs).__name__}")
        if envs is not native:
            # the adapter steps the native env: gymnasium's wrappers around it would be
            # skipped without a word (a reward scaled by 1000 came back unscaled, an audit)
            raise ValueError(f"envs must be the bare StarSwimmerVectorEnv, got it wrapped in "
                             f"{type(envs).__name__}: wrap to_sb3's result in SB3's own "
                             f"wrappers instead (VecNormalize, VecMonitor, ...)")
        self.envs = native
        self.num_envs = native.num_envs
        self.observation_space = native.single_observation_space
        self.action_space = native.single_action_space
        self.render_mode = native.render_mode
        self.metadata = {"render_modes": list(native.metadata["render_modes"])}
        self.reset_infos: List[Dict[str, Any]] = [{} for _ in range(self.num_envs)]
        self._seeds: List[Optional[int]] = [None] * self.num_envs
        self._options: List[Dict[str, Any]] = [{} for _ in range(self.num_envs)]
        self._actions = None

    # ------------------------------------------------------------------ stepping
    def reset(self) -> np.ndarray:
        """Reset every robot (with the seeds and options set since the last reset, then
        forgotten); returns the (num_envs, 15) float32 observations."""
        options = _native_options(self._options)
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        observation, info = self.envs.reset(seed=seeds, options=options or None)
        self.reset_infos = _rows_of(info, self.num_envs)
        self._seeds = [None] * self.num_envs
        self._options = [{} for _ in range(self.num_envs)]
        return observation

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        """Step with the actions given to `step_async`; returns observations (num_envs, 15)
        float32, rewards (num_envs,) float32, dones (num_envs,) bool and infos (a list of
        dicts), robots whose episode ended reset in the same step."""
        observation, rewards, terminated, truncated, info = self.envs.step(self._actions)
        dones = terminated | truncated
        infos = _rows_of(info, self.num_envs)
        for row in range(self.num_envs):
            infos[row]["TimeLimit.truncated"] = bool(truncated[row] and not terminated[row])
        if dones.any():
            for row in np.flatnonzero(dones):
                infos[row]["terminal_observation"] = observation[row]
            first, reset_info = self.envs.reset(options={"reset_mask": dones})
            observation = np.where(dones[:, None], first, observation)
            reset_rows = _rows_of(reset_info, self.num_envs)
            for row in np.flatnonzero(dones):
                self.reset_infos[row] = reset_rows[row]
        return observation, rewards.astype(np.float32), dones, infos

    def step(self, actions: np.ndarray):
        self.step_async(actions)
        return self.step_wait()

    def seed(self, seed: Optional[int] = None) -> List[int]:
        """Seeds for the next reset: robot b gets seed + b (a random seed when None)."""
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        if not is_whole(seed) or seed < 0:
            raise ValueError(f"seed must be an int >= 0 or None, got {seed!r}")
        self._seeds = [int(seed) + b for b in range(self.num_envs)]
        return self._seeds

    def set_options(self, options=None) -> None:
        """Options for the next reset: one dict for every robot, or a list of num_envs dicts
        (what SB3 passes): equal ones, or each with its own goal ({"goal": (x_mm, y_mm)})."""
        if options is None:
            options = {}
        self._options = ([dict(options) for _ in range(self.num_envs)]
                         if isinstance(options, dict) else [dict(o) for o in options])

    def close(self) -> None:
        self.envs.close()

    # ------------------------------------------------------------------ attributes
    def _indices(self, indices) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        return [indices] if isinstance(indices, numbers.Integral) else list(indices)

    def get_attr(self, attr_name: str, indices=None) -> List[Any]:
        value = getattr(self.envs, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.envs, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs):
        result = getattr(self.envs, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> List[bool]:
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[Optional[np.ndarray]]:
        """One (400, 400, 3) uint8 picture per robot with render_mode "rgb_array"; Nones
        otherwise."""
        pictures = self.envs.render()
        return list(pictures) if pictures is not None else [None] * self.num_envs


@functools.lru_cache(maxsize=None)
def _sb3_class(base: type) -> type:
    """SB3VectorAdapter made a subclass of SB3's VecEnv (its methods first)."""
    return type("StarSwimmerSB3VecEnv", (SB3VectorAdapter, base), {"__module__": __name__})


def to_sb3(envs: StarSwimmerVectorEnv):
    """`envs` (a StarSwimmerVectorEnv, e.g. from `gymnasium.make_vec("StarSwimmer-v0",
    num_envs=64)`) as a Stable-Baselines3 VecEnv (see the module docstring). ImportError
    without stable-baselines3 (`pip install stable-baselines3`)."""
    try:
        from stable_baselines3.common.vec_env import VecEnv
    except ImportError as error:
        raise ImportError("to_sb3 needs stable-baselines3: pip install stable-baselines3") \
            from error
    return _sb3_class(VecEnv)(envs)
