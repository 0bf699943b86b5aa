"""The Gymnasium environments: gymnasium's own checker on the single env; the native vector
env against gymnasium's SyncVectorEnv of single envs (same seeds and actions: bitwise the same
observations, rewards, episode ends and autoresets); the vector API (spaces, dtypes, seeding,
reset_mask, info masks); a value check of the reward; bad input."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import batch_space

import taichi_star as ts
from taichi_star.envs import (DEFAULT_MAX_EPISODE_STEPS, ENV_ID, OBSERVATION_NAMES,
                              StarSwimmerEnv, StarSwimmerVectorEnv)

# the paper's actuation period at a coarse step: 630 steps per control period
KWARGS = dict(solver=ts.SolverConfig(dt=5e-3))
FORWARD = ts.Gait.parse("A1+A2+A8").mask  # swims along +x (its forward direction) at 3.4 mm/s
BACKWARD = ts.Gait.parse("A4+A5+A6").mask  # its mirror image: along -x


@pytest.fixture(scope="module")
def single():
    return gym.make(ENV_ID, **KWARGS)


def test_single_env_passes_gymnasiums_checker(single):
    check_env(single.unwrapped)
    assert single.observation_space.shape == (len(OBSERVATION_NAMES),)
    assert single.observation_space.dtype == np.float32
    assert single.action_space == gym.spaces.MultiBinary(8)


def test_forward_gait_toward_a_goal_ahead_is_rewarded(single):
    """A1+A2+A8 swims along +x: toward a goal 30 mm ahead it gains about its 3.15-s stroke
    (~8 mm from rest) less the firing cost; the mirror gait loses as much."""
    single.reset(options={"goal": (30.0, 0.0)})
    observation, reward, terminated, truncated, info = single.step(FORWARD)
    assert 5.0 < reward < 12.0 and not terminated and not truncated
    assert observation[0] < 30.0 - 5.0 and info["position_mm"][0] > 5.0
    fired_ago = np.float32([3.15, 3.15, 10, 10, 10, 10, 10, 3.15])  # 10 s: the never-fired cap
    np.testing.assert_array_equal(observation[7:], fired_ago)
    single.reset(options={"goal": (30.0, 0.0)})
    assert single.step(BACKWARD)[1] < -5.0


def test_reaching_the_goal_terminates(single):
    single.reset(options={"goal": (2.0, 0.0)})
    _, reward, terminated, truncated, info = single.step(np.zeros(8, dtype=np.int8))
    # an unfired robot stays at rest (to round-off)
    assert terminated and not truncated and abs(reward) < 1e-9
    assert info["distance_mm"] == pytest.approx(2.0, abs=1e-9)


def test_reset_is_reproducible_and_goals_follow_the_seed(single):
    first, info = single.reset(seed=7)
    again, _ = single.reset(seed=7)
    other, _ = single.reset(seed=8)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first[:2], other[:2])
    assert np.hypot(*info["goal_mm"]) == pytest.approx(50.0)


def test_make_vec_builds_the_native_vector_env():
    envs = gym.make_vec(ENV_ID, num_envs=2, **KWARGS)
    assert isinstance(envs, StarSwimmerVectorEnv)
    assert envs.batch.simulator.n_instances == 2  # one engine for all robots, not copies
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.batch.task.max_episode_steps == DEFAULT_MAX_EPISODE_STEPS


def test_make_and_make_vec_take_the_step_budget():
    single = gym.make(ENV_ID, max_episode_steps=1, **KWARGS)
    single.reset(seed=0)
    assert single.step(np.zeros(8, dtype=np.int8))[3]
    envs = gym.make_vec(ENV_ID, num_envs=2, max_episode_steps=1, **KWARGS)
    envs.reset(seed=0)
    assert envs.step(np.zeros((2, 8), dtype=np.int8))[3].all()


def actions_schedule(steps, num_envs):
    """Per step a (num_envs, 8) action: robot 0 never fires (its goal 2 mm away: it terminates
    at once), the others fire a fixed pattern (their episodes are truncated)."""
    rng = np.random.default_rng(0)
    actions = rng.integers(0, 2, size=(steps, num_envs, 8), dtype=np.int8)
    actions[:, 0] = 0
    return actions


def test_vector_env_equals_sync_vector_env_of_single_envs():
    """Robot b of the native vector env is a single env seeded with seed + b: observations,
    rewards, terminations, truncations and NEXT_STEP autoresets are bitwise those of
    gymnasium's SyncVectorEnv over single envs."""
    num_envs, steps = 3, 5
    task = dict(KWARGS, max_episode_steps=2, goal_distance_mm=20.0)
    native = StarSwimmerVectorEnv(num_envs, **task)
    reference = SyncVectorEnv([lambda: StarSwimmerEnv(**task) for _ in range(num_envs)],
                              autoreset_mode=AutoresetMode.NEXT_STEP)
    observations = [env.reset(seed=11)[0] for env in (native, reference)]
    np.testing.assert_array_equal(*observations)
    # robot 0 starts again with its goal within the tolerance: it terminates at once
    for env in (native, reference):
        env.reset(options={"goal": (2.0, 0.0), "reset_mask": np.array([True, False, False])})
    ends = np.zeros(num_envs, dtype=int)
    for actions in actions_schedule(steps, num_envs):
        got = native.step(actions)
        expected = reference.step(actions)
        for name, a, b in zip(("observation", "reward", "terminated", "truncated"), got, expected):
            np.testing.assert_array_equal(a, b, err_msg=name)
            assert a.dtype == b.dtype or name == "observation", name
        np.testing.assert_array_equal(got[4]["distance_mm"], expected[4]["distance_mm"])
        ends += got[2] | got[3]
    assert (ends == 2).all()  # robot 0 terminated then was truncated, the others truncated


def test_vector_env_api():
    num_envs = 2
    envs = StarSwimmerVectorEnv(num_envs, **KWARGS)
    assert envs.observation_space == batch_space(envs.single_observation_space, num_envs)
    assert envs.action_space == batch_space(envs.single_action_space, num_envs)
    observation, info = envs.reset(seed=3)
    assert observation.shape == (num_envs, len(OBSERVATION_NAMES))
    assert observation.dtype == np.float32 and observation in envs.observation_space
    assert info["goal_mm"].shape == (num_envs, 2) and info["_goal_mm"].all()
    again, _ = envs.reset(seed=3)
    np.testing.assert_array_equal(observation, again)
    assert not np.array_equal(observation[0, :2], observation[1, :2])  # seeds 3 and 4
    envs.action_space.seed(0)
    observation, reward, terminated, truncated, info = envs.step(envs.action_space.sample())
    assert observation in envs.observation_space and observation.dtype == np.float32
    assert reward.shape == (num_envs,) and reward.dtype == np.float64
    assert terminated.dtype == truncated.dtype == bool
    np.testing.assert_allclose(info["time_s"], 3.15)
    # reset_mask: robot 1 keeps swimming, robot 0 starts again
    envs.reset(options={"reset_mask": np.array([True, False])})
    np.testing.assert_array_equal(envs.batch.simulator.time_s, [0.0, 3.15])


def test_bad_input_raises_value_error_and_changes_nothing():
    envs = StarSwimmerVectorEnv(2, **KWARGS)
    envs.reset(seed=0)
    before = envs.batch.simulator.save()
    for actions, words in ((np.zeros((2, 7), np.int8), "shape"),
                           (np.zeros(8, np.int8), "shape"),
                           (np.full((2, 8), 0.5), "dtype"),
                           (np.full((2, 8), 2), "0/1")):
        with pytest.raises(ValueError, match=words):
            envs.step(actions)
    for goal in ((np.nan, 0.0), (np.inf, 1.0), (1.0, 2.0, 3.0), (5e3, 0.0)):
        with pytest.raises(ValueError, match="goal"):
            envs.reset(options={"goal": goal})
    for name, value in (("goal_distance_mm", -1.0), ("goal_tolerance_mm", np.nan),
                        ("max_episode_steps", 0), ("firing_cost_mm", -0.1)):
        with pytest.raises(ValueError, match=name):
            StarSwimmerEnv(**KWARGS, **{name: value})
    with pytest.raises(ValueError, match="control_period_s"):
        StarSwimmerEnv(**KWARGS, control_period_s=1.0021)
    with pytest.raises(ValueError, match="control_period_s"):
        StarSwimmerEnv(**KWARGS, control_period_s=-3.15)
    after = envs.batch.simulator.save()
    for name, values in before.fields.items():
        np.testing.assert_array_equal(values, after.fields[name], err_msg=name)

