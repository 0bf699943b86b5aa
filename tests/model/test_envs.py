"""The Gymnasium environments: gymnasium's own checker on the single env; the native vector
env against gymnasium's SyncVectorEnv of single envs (same seeds and actions: bitwise the same
observations, rewards, episode ends and autoresets); the vector API (spaces, dtypes, seeding,
reset_mask, info masks); a value check of the reward; bad input; float actions as RL
libraries emit them; the rgb_array render; the Stable-Baselines3 adapter against SB3's VecEnv
contract (same-step autoreset, terminal_observation), and, when stable-baselines3 is installed,
PPO on both paths."""

import re
import sys
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from gymnasium.vector.utils import batch_space

import taichi_star as ts
from taichi_star.envs import (DEFAULT_MAX_EPISODE_STEPS, ENV_ID, OBSERVATION_NAMES,
                              SB3VectorAdapter, StarSwimmerEnv, StarSwimmerVectorEnv, SwimmerTask,
                              control_period, to_sb3)
from taichi_star.metrics import rotate

# the paper's actuation period at a coarse step: 630 steps per control period
KWARGS = dict(solver=ts.SolverConfig(dt=5e-3))
# 10 steps per control period, within the 0.163-s heating pulse: cheap steps for API tests
SHORT = dict(KWARGS, control_period_s=0.05)
FORWARD = ts.Gait.parse("A1+A2+A8").mask  # swims along +x (its forward direction) at 3.4 mm/s
BACKWARD = ts.Gait.parse("A4+A5+A6").mask  # its mirror image: along -x


@pytest.fixture
def single():
    # per test, closed after it: its engine goes back for the next env (no compilation), and
    # no env of this file is kept open beside those a test makes
    env = gym.make(ENV_ID, **KWARGS)
    yield env
    env.close()


def test_single_env_passes_gymnasiums_checker():
    # the checker steps and resets a dozen times: a 50-ms control period keeps it cheap (the
    # spaces and API it checks do not depend on the period); the envs it makes from the spec
    # and closes, and this one once closed, hand their engine on (no `single` is alive yet)
    env = gym.make(ENV_ID, **SHORT).unwrapped
    check_env(env)
    assert env.observation_space.shape == (len(OBSERVATION_NAMES),)
    assert env.observation_space.dtype == np.float32
    assert env.action_space == gym.spaces.MultiBinary(8)
    env.close()


def test_a_closed_env_hands_its_engine_to_the_next_and_refuses_to_step():
    first = gym.make(ENV_ID, **SHORT)
    first.reset(seed=5)
    expected = [first.step(FORWARD)[0] for _ in range(2)]
    engine = first.unwrapped.simulator.engine
    # make's environment is wrapped: its properties are the unwrapped one's (docs/control.md)
    assert first.get_wrapper_attr("simulator") is first.unwrapped.simulator
    assert first.unwrapped.control_period_s == SHORT["control_period_s"]
    first.close()
    first.close()  # gymnasium allows closing twice
    for call in (lambda: first.reset(seed=5), lambda: first.step(FORWARD)):
        with pytest.raises(RuntimeError, match="closed"):
            call()
    # the same topology, terms, integrator and capacity (every batch up to 64 robots): the
    # closed env's engine, not a new compilation, and from a reset it gives the same bits
    second = gym.make(ENV_ID, **SHORT)
    assert second.unwrapped.simulator.engine is engine
    second.reset(seed=5)
    np.testing.assert_array_equal([second.step(FORWARD)[0] for _ in range(2)], expected)
    # while `second` is open its engine is its own: the vector env gets another
    vector = StarSwimmerVectorEnv(2, **SHORT)
    assert vector.simulator.engine is not engine
    vector.close()
    assert vector.closed
    with pytest.raises(RuntimeError, match="closed"):
        vector.reset(seed=5)
    # the public Simulator is gone with it, as the episodes are
    with pytest.raises(RuntimeError, match="closed"):
        vector.simulator
    second.close()


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


def test_a_bad_seed_is_a_value_error_and_changes_no_robot(single):
    """Gymnasium's generators take None or an int >= 0: anything else is refused with a
    ValueError naming it (was gymnasium's own error), and in the vector env before any robot's
    generator is replaced (robot 0's was, before robot 1's seed was found bad)."""
    for seed, message in ((-1, "seed must be None or an integer >= 0, got -1"),
                          (1.5, "seed must be None or an integer >= 0, got 1.5"),
                          (True, "seed must be None or an integer >= 0, got True")):
        with pytest.raises(ValueError) as error:
            single.reset(seed=seed)
        assert str(error.value) == message
    envs = StarSwimmerVectorEnv(2, **SHORT)
    envs.reset(seed=3)
    generators = [generator.bit_generator.state for generator in envs._generators]
    for seed, message in (([1, -2], "seed[1] must be None or an integer >= 0, got -2"),
                          (-1, "seed must be None or an integer >= 0, got -1")):
        with pytest.raises(ValueError) as error:
            envs.reset(seed=seed)
        assert str(error.value) == message
        assert [g.bit_generator.state for g in envs._generators] == generators
    replaced, kept = envs._generators
    envs.reset(seed=[0, None])   # 0 is a seed, None keeps robot 1's generator going
    assert envs._generators[0] is not replaced and envs._generators[1] is kept
    # a NumPy integer seeds as the int does (the vector env's own generator raised gymnasium's
    # "Seed must be a python integer"; an audit)
    by_int, _ = envs.reset(seed=3)
    by_numpy, _ = envs.reset(seed=np.int64(3))
    np.testing.assert_array_equal(by_numpy, by_int)
    # one seed per robot as a NumPy array, as gymnasium's vector envs take them (refused: an
    # audit, 2026-12), the same as the list; a 2-D array or one of another length refused
    by_list, _ = envs.reset(seed=[3, 7])
    by_array, _ = envs.reset(seed=np.array([3, 7]))
    np.testing.assert_array_equal(by_array, by_list)
    for seed in (np.array([[3, 7]]), np.array([3, 7, 9])):
        with pytest.raises(ValueError, match=r"^seed must be None, an int or a list of 2 seeds"):
            envs.reset(seed=seed)
    envs.close()


@pytest.mark.parametrize("distance_mm, refused", [(4.0, True), (5.0, True), (5.5, False),
                                                  (5.000001, False), (4.9999999, True)])
def test_a_task_whose_goals_would_start_reached_is_refused(distance_mm, refused):
    """Goals drawn at goal_distance_mm within goal_tolerance_mm (5 mm) of the start end every
    episode at its first step, whatever the agent does (accepted: an audit, 2026-12): refused
    at the tolerance itself too; just past it accepted."""
    if refused:
        with pytest.raises(ValueError, match=re.escape(
                f"goal_distance_mm must exceed goal_tolerance_mm (5.0 mm), got {distance_mm!r}")):
            SwimmerTask(goal_distance_mm=distance_mm)
    else:
        assert SwimmerTask(goal_distance_mm=distance_mm).goal_distance_mm == distance_mm


def test_make_vec_builds_the_native_vector_env():
    envs = gym.make_vec(ENV_ID, num_envs=2, **KWARGS)
    assert isinstance(envs, StarSwimmerVectorEnv)
    assert envs.simulator.n_instances == 2  # one engine for all robots, not copies
    # one step is one control period, by default the actuation period of the robot
    assert envs.control_period_s == ts.StarParams().period
    assert envs.simulator.n_nodes == 193  # the paper robot's 8 × (18 + 6) + 1 nodes
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.batch.task.max_episode_steps == DEFAULT_MAX_EPISODE_STEPS


def test_make_and_make_vec_take_the_step_budget():
    single = gym.make(ENV_ID, max_episode_steps=1, **KWARGS)
    single.reset(seed=0)
    assert single.step(np.zeros(8, dtype=np.int8))[3]
    envs = gym.make_vec(ENV_ID, num_envs=2, max_episode_steps=1, **KWARGS)
    envs.reset(seed=0)
    assert envs.step(np.zeros((2, 8), dtype=np.int8))[3].all()
    single.close()
    envs.close()


def test_a_goal_reached_on_the_budgets_last_step_is_terminated_and_truncated_everywhere():
    """As gymnasium's TimeLimit: the budget's last step is truncated even when the goal is
    reached on it. The native vector env said truncated = False there, while `make`'s wrapped
    env and so a SyncVectorEnv of them said True (an audit, 2026-12); all three agree now, and
    a robot reaching its goal with budget left is terminated alone. The SB3 adapter's
    TimeLimit.truncated stays False (the episode ended at its goal)."""
    zeros = np.zeros((2, 8), np.int8)
    native = gym.make_vec(ENV_ID, num_envs=2, max_episode_steps=1, **SHORT)
    synchronous = gym.make_vec(ENV_ID, num_envs=2, max_episode_steps=1,
                               vectorization_mode="sync", **SHORT)
    for envs in (native, synchronous):
        envs.reset(seed=0, options={"goal": (2.0, 0.0)})
        terminated, truncated = envs.step(zeros)[2:4]
        assert terminated.tolist() == truncated.tolist() == [True, True]
        envs.close()
    roomy = StarSwimmerVectorEnv(2, max_episode_steps=2, **SHORT)
    roomy.reset(seed=0, options={"goal": (2.0, 0.0)})
    terminated, truncated = roomy.step(zeros)[2:4]
    assert terminated.tolist() == [True, True] and truncated.tolist() == [False, False]
    roomy.close()
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, max_episode_steps=1, **SHORT))
    adapter.set_options({"goal": (2.0, 0.0)})
    adapter.reset()
    _, _, dones, infos = adapter.step(zeros)
    assert dones.all() and [info["TimeLimit.truncated"] for info in infos] == [False, False]
    adapter.close()


def test_a_refused_reset_leaves_the_generator_and_a_closed_env_says_closed_first():
    """A reset refused for its goal had already replaced the single env's generator (an
    audit, 2026-12); a closed vector env never reset answered "call reset() before step()",
    and a closed env without a render mode rendered None, where the docs promise "closed"."""
    env = StarSwimmerEnv(**SHORT)
    env.reset(seed=1)
    state = env.np_random.bit_generator.state
    with pytest.raises(ValueError, match="goal"):
        env.reset(seed=99, options={"goal": (np.nan, 0.0)})
    assert env.np_random.bit_generator.state == state
    env.close()
    with pytest.raises(RuntimeError, match="closed"):
        env.render()
    envs = StarSwimmerVectorEnv(2, **SHORT)
    envs.close()
    for call in (lambda: envs.step(np.zeros((2, 8), np.int8)), envs.render):
        with pytest.raises(RuntimeError, match="^this environment is closed"):
            call()


def test_a_partial_resets_info_marks_the_robots_it_reset():
    """SyncVectorEnv's info after a reset of some robots holds those robots alone (its "_key"
    masks); the native env marked every robot. The values themselves are every robot's."""
    envs = StarSwimmerVectorEnv(2, **SHORT)
    _, info = envs.reset(seed=0)
    assert info["_goal_mm"].tolist() == [True, True]
    _, info = envs.reset(options={"reset_mask": np.array([False, True])})
    assert all(info[f"_{key}"].tolist() == [False, True] for key in info
               if not key.startswith("_"))
    reference = SyncVectorEnv([lambda: StarSwimmerEnv(**SHORT) for _ in range(2)])
    reference.reset(seed=0)
    _, expected = reference.reset(options={"reset_mask": np.array([False, True])})
    assert expected["_goal_mm"].tolist() == [False, True]
    np.testing.assert_array_equal(info["goal_mm"][1], expected["goal_mm"][1])
    envs.close()
    reference.close()


def test_sb3s_per_robot_options_are_one_options_dict_or_per_robot_goals():
    """SB3's `set_options(list)` gives one dict per robot: equal dicts holding arrays raised
    NumPy's "truth value of an array is ambiguous" (an audit, 2026-12), and a goal per robot
    was refused; both reach the native env now, and dicts that differ in more than their goal
    are refused naming set_options."""
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **SHORT))
    goal = np.array([10.0, 0.0])
    adapter.set_options([{"goal": goal}, {"goal": goal.copy()}])
    adapter.reset()
    np.testing.assert_array_equal([info["goal_mm"] for info in adapter.reset_infos], [goal] * 2)
    adapter.set_options([{"goal": (10.0, 0.0)}, {"goal": np.array([0.0, -20.0])}])
    observation = adapter.reset()
    np.testing.assert_array_equal([info["goal_mm"] for info in adapter.reset_infos],
                                  [[10.0, 0.0], [0.0, -20.0]])
    np.testing.assert_allclose(np.hypot(observation[:, 0], observation[:, 1]), [10.0, 20.0],
                               rtol=1e-6)   # float32 observations of the robots at rest
    adapter.set_options([{"goal": goal}, {"goal": goal, "reset_mask": np.array([True, True])}])
    with pytest.raises(ValueError, match=r"^set_options: the robots' options may differ only in "
                                         r"their goals"):
        adapter.reset()
    adapter.close()


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
    # two robots: one reset alone below, one not (each single env compiles an engine of its own)
    num_envs, steps = 2, 5
    # the short control period: no robot gets near a 20-mm goal in it, so the ends come from
    # the goal within tolerance and the step budget alone, as with any period
    task = dict(SHORT, max_episode_steps=2, goal_distance_mm=20.0)
    native = StarSwimmerVectorEnv(num_envs, **task)
    reference = SyncVectorEnv([lambda: StarSwimmerEnv(**task) for _ in range(num_envs)],
                              autoreset_mode=AutoresetMode.NEXT_STEP)
    observations = [env.reset(seed=11)[0] for env in (native, reference)]
    np.testing.assert_array_equal(*observations)
    # robot 0 starts again with its goal within the tolerance: it terminates at once
    for env in (native, reference):
        env.reset(options={"goal": (2.0, 0.0), "reset_mask": np.array([True, False])})
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
    native.close()
    reference.close()


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


def test_a_robot_is_stepped_only_after_its_first_reset_and_a_solver_must_be_one():
    """A bare vector env stepped before reset ended every episode at once, at the goal (0, 0)
    the robots start on (gymnasium's wrappers enforce the order; the bare env did not); a
    solver given as a text failed reading its dt (AttributeError). An audit, 2026-12."""
    envs = StarSwimmerVectorEnv(2, **SHORT)
    actions = np.zeros((2, 8), np.int8)
    with pytest.raises(RuntimeError, match=r"^call reset\(\) before step\(\): robot 0 has no "
                                           r"episode yet$"):
        envs.step(actions)
    assert envs.batch.simulator.time_s.tolist() == [0.0, 0.0]   # nothing fired or advanced
    envs.reset(seed=0)
    _, _, terminated, truncated, _ = envs.step(actions)
    assert not (terminated | truncated).any()
    envs.close()
    for make in (lambda: StarSwimmerVectorEnv(2, solver="paper"),
                 lambda: StarSwimmerEnv(solver="paper")):
        with pytest.raises(ValueError, match="^solver must be a SolverConfig, got str$"):
            make()


def test_bad_input_raises_value_error_and_changes_nothing():
    envs = StarSwimmerVectorEnv(2, **KWARGS)
    envs.reset(seed=0)
    before = envs.batch.simulator.save()
    for actions, words in ((np.zeros((2, 7), np.int8), "shape"),
                           (np.zeros(8, np.int8), "shape"),
                           (np.full((2, 8), 0.5), "0 and 1"),
                           (np.full((2, 8), 2), "0 and 1"),
                           (np.full((2, 8), 2.0, np.float32), "0 and 1"),
                           (np.full((2, 8), np.nan), "0 and 1"),
                           (np.full((2, 8), "1"), "0 and 1"),
                           # a TypeError and NumPy's words, naming no action (an audit, 2026-12)
                           ([[0, 1, 0, 0, 0, 0, 0, None]] * 2,
                            r"0 and 1 .* values \[None, None\]$"),
                           ([[0, [1, 2]]] * 2,
                            r"^action must be an array of shape \(2, 8\) of 0 and 1, got a "
                            r"ragged list$")):
        with pytest.raises(ValueError, match=words):
            envs.step(actions)
    for goal in ((np.nan, 0.0), (np.inf, 1.0), (1.0, 2.0, 3.0), (5e3, 0.0)):
        with pytest.raises(ValueError, match="goal"):
            envs.reset(options={"goal": goal})
    with pytest.raises(ValueError, match=r"unknown keys \['gaol'\]"):
        envs.reset(options={"gaol": (10.0, 0.0)})
    with pytest.raises(ValueError, match="options must be a dict"):
        envs.reset(options=[("goal", (10.0, 0.0))])
    with pytest.raises(ValueError, match="render_mode"):
        StarSwimmerVectorEnv(2, render_mode="human", **KWARGS)
    for name, value in (("goal_distance_mm", -1.0), ("goal_tolerance_mm", np.nan),
                        ("max_episode_steps", 0), ("firing_cost_mm", -0.1)):
        with pytest.raises(ValueError, match=name):
            StarSwimmerEnv(**KWARGS, **{name: value})
    with pytest.raises(ValueError, match="control_period_s"):
        StarSwimmerEnv(**KWARGS, control_period_s=1.0021)
    with pytest.raises(ValueError, match="control_period_s"):
        StarSwimmerEnv(**KWARGS, control_period_s=-3.15)
    # past the steps a run may take: refused when the environment is made (at its first step
    # before, naming duration_s)
    with pytest.raises(ValueError, match=r"^control_period_s = 1e\+08 s at dt = 0.005 s"):
        StarSwimmerEnv(**KWARGS, control_period_s=1e8)
    after = envs.batch.simulator.save()
    for name, values in before.fields.items():
        np.testing.assert_array_equal(values, after.fields[name], err_msg=name)



@pytest.mark.parametrize("distance_mm, refused", [(1000.0, False), (1000.5, True)])
def test_a_goal_a_metre_away_is_accepted_and_one_past_it_refused(single, distance_mm, refused):
    """metrics.MAX_GOAL_MM (1 m) bounds a goal, the metre itself included: a task's
    goal_distance_mm and a reset's options['goal'] of exactly 1000 mm are accepted, 1000.5 mm
    refused naming the field and its range."""
    if refused:
        with pytest.raises(ValueError, match=r"^goal_distance_mm must be a number in \(0, "
                                             r"1000\], got 1000.5$"):
            SwimmerTask(goal_distance_mm=distance_mm)
        with pytest.raises(ValueError, match=r"^options\['goal'\] must be within 1000 mm of "
                                             r"the start, got \(1000.5, 0.0\)$"):
            single.reset(options={"goal": (distance_mm, 0.0)})
    else:
        assert SwimmerTask(goal_distance_mm=distance_mm).goal_distance_mm == distance_mm
        _, info = single.reset(options={"goal": (distance_mm, 0.0)})
        np.testing.assert_array_equal(info["goal_mm"], [distance_mm, 0.0])


def test_an_unknown_keyword_and_a_render_mode_without_matplotlib_are_refused_when_made(
        monkeypatch):
    """An unknown keyword was a TypeError of the task's dataclass; "rgb_array" without
    matplotlib (not in the envs or rl extras) failed at the first render, after the run, with a
    bare ModuleNotFoundError (an audit)."""
    with pytest.raises(ValueError, match=r"^unknown keyword 'goal_mm': an environment takes "
                                         r"params, solver, control_period_s, arch, render_mode "
                                         r"and the task's \['goal_distance_mm'"):
        StarSwimmerEnv(goal_mm=3, **SHORT)
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    for make in (lambda: StarSwimmerEnv(render_mode="rgb_array", **SHORT),
                 lambda: StarSwimmerVectorEnv(2, render_mode="rgb_array", **SHORT)):
        with pytest.raises(ImportError, match=r"taichi_star\[plots\]"):
            make()


def test_single_env_refuses_unknown_reset_options(single):
    with pytest.raises(ValueError, match=r"unknown keys \['gaol'\]; the allowed keys are \['goal'\]"):
        single.reset(options={"gaol": (10.0, 0.0)})
    with pytest.raises(ValueError, match="options must be a dict"):
        single.reset(options="goal")
    with pytest.raises(ValueError, match="unknown keys"):  # reset_mask is the vector env's
        single.reset(options={"reset_mask": np.array([True])})


def test_float_actions_of_a_policy_equal_integer_actions():
    """RL libraries sample MultiBinary as float32 0./1.: a step with them is bitwise the step
    with the same 0/1 as int8 (and as bool)."""
    results = []
    envs = StarSwimmerVectorEnv(2, **SHORT)
    for dtype in (np.float32, np.float64, np.int8, bool):
        envs.reset(seed=5)
        actions = np.array([[1, 1, 0, 0, 0, 0, 0, 1], [0, 0, 0, 1, 1, 1, 0, 0]], dtype=dtype)
        assert actions[0] in envs.single_action_space  # MultiBinary(8) accepts each dtype
        results.append(envs.step(actions)[:2])
    for observation, reward in results[1:]:
        np.testing.assert_array_equal(observation, results[0][0])
        np.testing.assert_array_equal(reward, results[0][1])
    assert results[0][0][0, 7] < 0.1 and results[0][0][1, 7] == 10.0  # A1 fired by robot 0 only
    # Python objects 0 and 1, which MultiBinary holds, too (refused until 2026-12)
    envs.reset(seed=5)
    actions = np.array([[1, 1, 0, 0, 0, 0, 0, 1], [0, 0, 0, 1, 1, 1, 0, 0]], dtype=object)
    assert actions[0] in envs.single_action_space
    observation, reward = envs.step(actions)[:2]
    np.testing.assert_array_equal(observation, results[0][0])
    np.testing.assert_array_equal(reward, results[0][1])
    envs.close()


def red_pixels(picture):
    return int(((picture[..., 0] > 200) & (picture[..., 1] < 60) & (picture[..., 2] < 60)).sum())


def test_rgb_array_render_shows_the_heating_actuators():
    """render_mode "rgb_array" is declared (gymnasium.make gives no warning) and draws the
    robot: no red before firing, red arcs while the fired actuators heat (the 0.05-s step ends
    inside the 0.163-s pulse)."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(ENV_ID, render_mode="rgb_array", **SHORT)
    env.reset(seed=0)
    before = env.render()
    assert before.shape == (400, 400, 3) and before.dtype == np.uint8
    assert red_pixels(before) == 0
    env.step(ts.Gait.parse("A1+A2").mask)
    assert red_pixels(env.render()) > 200
    assert StarSwimmerEnv(**SHORT).render() is None
    envs = StarSwimmerVectorEnv(2, render_mode="rgb_array", **SHORT)
    envs.reset(seed=0)
    pictures = envs.render()
    assert len(pictures) == 2 and pictures[1].shape == (400, 400, 3)


def test_sb3_adapter_resets_in_the_same_step_and_keeps_the_final_observation():
    """SB3's VecEnv contract, checked without SB3: float32 actions; step returns float32
    rewards, bool dones and a list of info dicts; a finished episode is reset within the step
    (the observation is the new episode's first, 50 mm from a new goal, nothing fired) and its
    final observation is info["terminal_observation"], equal to what the native env returned."""
    task = dict(SHORT, max_episode_steps=2)
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **task))
    native = StarSwimmerVectorEnv(2, **task)
    adapter.seed(21)
    observation = adapter.reset()
    np.testing.assert_array_equal(observation, native.reset(seed=21)[0])
    assert adapter.reset_infos[1]["goal_mm"].shape == (2,)
    actions = np.ones((2, 8), dtype=np.float32)
    first = adapter.step(actions)
    np.testing.assert_array_equal(first[0], native.step(actions)[0])
    assert not first[2].any() and first[1].dtype == np.float32 and len(first[3]) == 2
    observation, rewards, dones, infos = adapter.step(actions)
    final = native.step(actions)
    np.testing.assert_array_equal(rewards, final[1].astype(np.float32))
    assert dones.all() and dones.dtype == bool
    for row in range(2):
        np.testing.assert_array_equal(infos[row]["terminal_observation"], final[0][row])
        assert infos[row]["TimeLimit.truncated"] is True
        assert np.hypot(*observation[row, :2]) == pytest.approx(50.0, rel=1e-6)
        np.testing.assert_array_equal(observation[row, 7:], 10.0)  # never-fired cap
    # the next step continues the new episodes (no NEXT_STEP no-op step)
    assert not adapter.step(actions)[2].any()
    assert adapter.get_attr("num_envs") == [2, 2] and adapter.env_is_wrapped(object) == [False] * 2
    assert adapter.env_method("render", indices=[0]) == [None]
    with pytest.raises(ValueError, match="StarSwimmerVectorEnv"):
        SB3VectorAdapter(StarSwimmerEnv(**SHORT))
    # gymnasium's wrappers around the vector env: refused, not skipped without a word (a
    # reward wrapper's scaling was lost, an audit); a negative seed: refused at `seed`, not at
    # every later reset
    wrapped = gym.wrappers.vector.RecordEpisodeStatistics(adapter.envs)
    with pytest.raises(ValueError, match=r"^envs must be the bare StarSwimmerVectorEnv, got it "
                                         r"wrapped in RecordEpisodeStatistics"):
        SB3VectorAdapter(wrapped)
    with pytest.raises(ValueError, match=r"^seed must be an int >= 0 or None, got -1"):
        adapter.seed(-1)
    adapter.reset()  # the refused seed left nothing behind


def test_ppo_runs_on_both_paths_without_warnings(tmp_path, monkeypatch):
    """Optional (stable-baselines3 is not a test dependency; CI installs it where the machine
    keeps a CPU build of torch, .ci/run): PPO collects a rollout of 64 steps and trains on it,
    on the native vector env through `to_sb3` and on SB3's own `make_vec_env` of single envs,
    with every episode of 4 control periods ending and resetting inside the rollout. SB3's
    logger makes its folder even when it logs nothing, in the system's temporary folder unless
    SB3_LOGDIR names one: each run of the suite left two empty folders in /tmp."""
    pytest.importorskip("stable_baselines3")
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path))
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecMonitor

    # the paper's step of 1 ms, not KWARGS' 5 ms: an untrained policy fires at random, and a
    # hot actuator re-fired at 5 ms (or 2 ms) steps caps a Newton solve within 64 control
    # periods, which advance rightly warns about (test_an_env_is_not_copied_or_pickled_...
    # reads the flag) and this test would take for an interface fault
    task = dict(control_period_s=0.05, max_episode_steps=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for envs, n_steps in ((VecMonitor(to_sb3(StarSwimmerVectorEnv(8, **task))), 8),
                              (make_vec_env(ENV_ID, n_envs=2, env_kwargs=task), 32)):
            model = PPO("MlpPolicy", envs, n_steps=n_steps, batch_size=64, n_epochs=1,
                        device="cpu", seed=0)
            model.learn(64)
            assert model.logger.dir == str(tmp_path)
            assert model.num_timesteps == 64
            # 64 steps of 4-period episodes: every robot's episodes ended and restarted
            assert len(model.ep_info_buffer) == 64 // 4
            assert all(info["l"] == 4 for info in model.ep_info_buffer)


def test_an_env_is_not_copied_or_pickled_and_its_info_tells_capped_solves():
    """copy.copy of an environment shared its robot (stepping the copy moved the original),
    copy.deepcopy and pickle failed in Taichi's words (an audit, 2026-12): TypeErrors saying
    what to do, the original untouched. `info` names robots whose Newton solves were capped
    (`Simulator.state()`'s newton_capped), False for a plain robot."""
    import copy
    import pickle

    env = StarSwimmerEnv(**SHORT)
    try:
        env.reset(seed=0)
        for attempt in (copy.copy, copy.deepcopy, pickle.dumps):
            with pytest.raises(TypeError, match=r"an environment is not copied or pickled"):
                attempt(env)
        assert env.simulator.time_s.tolist() == [0.0]
        _, _, _, _, info = env.step(FORWARD)
        assert info["newton_capped"] is np.False_ or info["newton_capped"] == False  # noqa: E712
        assert info["status"] == "ok"
    finally:
        env.close()


def test_a_failed_robot_stepped_again_pays_no_firing_cost():
    """A robot whose solver failed ends its episode truncated; stepped again without a reset,
    its firings are ignored (the Simulator takes no command from it), and it paid the firing
    cost for them (an audit, 2026-12): its reward is now 0, its distance unchanged. The
    failing robot of the Simulator's tests: 50-ms steps, five Newton iterations."""
    env = StarSwimmerEnv(solver=ts.SolverConfig(dt=0.05, max_newton=5, max_substep_halvings=1),
                         control_period_s=0.4)
    env.reset(seed=0)
    a1 = np.zeros(8, dtype=int)
    a1[0] = 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # its capped solves
        _, _, terminated, truncated, info = env.step(a1)
        assert info["status"] == "newton_failed" and truncated and not terminated
        _, reward, _, truncated, info = env.step(a1)
    assert reward == 0.0 and truncated and info["status"] == "newton_failed"
    env.close()


# a mutation audit of the environments (2026-12): each test below failed a mutant the suite
# let live. A coarse robot, 5-ms steps, a 0.05-s control period
COARSE = ts.StarParams(n_arc=6, n_limb=2)
FAST = dict(params=COARSE, solver=ts.SolverConfig(dt=5e-3), control_period_s=0.05)
NO_FIRING = np.zeros(8, dtype=np.int8)


@pytest.fixture
def coarse_env():
    made = StarSwimmerEnv(**FAST)
    yield made
    made.close()


def test_the_lowest_end_of_each_task_range_is_in_or_out_as_its_bracket_says():
    """firing_cost_mm's range [0, 1000] takes 0; goal_tolerance_mm (0, 1000] and
    since_fired_cap_s (0, 1e6] refuse it."""
    assert SwimmerTask(firing_cost_mm=0.0).firing_cost_mm == 0.0
    for name, text in (("goal_tolerance_mm", r"\(0, 1000\]"),
                       ("since_fired_cap_s", r"\(0, 1e\+06\]")):
        with pytest.raises(ValueError, match=rf"^{name} must be a number in {text}, got 0.0$"):
            SwimmerTask(**{name: 0.0})


def test_a_control_period_of_zero_and_zero_robots_are_refused():
    """Each refused at 0, its range's open end, before an engine is made."""
    # and past a float's range: an OverflowError of math.isfinite (an audit, 2026-12)
    for period in (0.0, 10**400):
        with pytest.raises(ValueError, match=r"^control_period_s must be a positive whole "
                                             r"number"):
            control_period(COARSE, ts.SolverConfig(dt=5e-3), period)
    with pytest.raises(ValueError, match=r"^goal_distance_mm must be a number in \(0, 1000\], "
                                         r"got an integer of 401 digits$"):
        SwimmerTask(goal_distance_mm=10**400)
    with pytest.raises(ValueError, match=r"^num_envs must be an integer >= 1, got 0$"):
        StarSwimmerVectorEnv(0, **FAST)


def test_the_since_fired_bounds_start_at_zero(coarse_env):
    """The times since each actuator fired are in [0, cap]; the other entries symmetric."""
    space = coarse_env.observation_space
    np.testing.assert_array_equal(space.low[7:], 0.0)
    np.testing.assert_array_equal(space.high[7:], 10.0)
    np.testing.assert_array_equal(space.low[:7], -space.high[:7])


def test_drawn_goals_lie_in_every_direction(coarse_env):
    """Goals of 16 seeds fall on both sides of both axes, all at goal_distance_mm."""
    goals = np.array([coarse_env.reset(seed=seed)[1]["goal_mm"] for seed in range(16)])
    assert (goals[:, 1] < 0).any() and (goals[:, 1] > 0).any()
    assert (goals[:, 0] < 0).any() and (goals[:, 0] > 0).any()
    np.testing.assert_allclose(np.hypot(*goals.T), 50.0)


def test_an_off_axis_goals_distance_and_first_reward(coarse_env):
    """A goal (0, 30) is 30 mm away (not its x distance), and an unfired robot's first step
    earns ~0, not -30."""
    _, info = coarse_env.reset(options={"goal": (0.0, 30.0)})
    assert info["distance_mm"] == 30.0
    _, reward, terminated, truncated, _ = coarse_env.step(NO_FIRING)
    assert abs(reward) < 1e-9 and not terminated and not truncated


def test_a_robot_exactly_at_the_tolerance_is_terminated():
    """A tolerance equal to the distance an unfired step leaves (the same bits every time)
    terminates the episode: within it means at most it."""
    probe = StarSwimmerEnv(**FAST)
    probe.reset(options={"goal": (30.0, 0.0)})
    distance = probe.step(NO_FIRING)[4]["distance_mm"]
    probe.close()
    assert 29.0 < distance < 31.0
    env = StarSwimmerEnv(**FAST, goal_tolerance_mm=distance)
    env.reset(options={"goal": (30.0, 0.0)})
    _, _, terminated, truncated, info = env.step(NO_FIRING)
    env.close()
    assert info["distance_mm"] == distance and terminated and not truncated


def test_a_robot_failing_within_its_tolerance_is_terminated_not_truncated():
    """A failure is a truncation only short of the goal; the coarse robot fails at its first
    50-ms step (five Newton iterations) 2 mm from a goal it has then reached."""
    env = StarSwimmerEnv(params=COARSE, solver=ts.SolverConfig(dt=0.05, max_newton=5,
                                                               max_substep_halvings=1),
                         control_period_s=0.4)
    env.reset(options={"goal": (2.0, 0.0)})
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        _, _, terminated, truncated, info = env.step(ts.Gait.parse("A1").mask)
    env.close()
    assert info["status"] == "newton_failed" and terminated and not truncated


def test_the_goal_and_the_velocity_are_observed_in_the_body_frame(coarse_env):
    """A chiral firing (A1+A2+A4) turns the robot; the observation's goal and velocity are
    the world vectors turned by -heading."""
    coarse_env.reset(options={"goal": (30.0, 20.0)})
    observation, _, _, _, info = coarse_env.step(ts.Gait.parse("A1+A2+A4").mask)
    heading = np.radians(info["heading_deg"])
    assert abs(heading) > 1e-5
    state = coarse_env.simulator.state()
    velocity = state[["velocity_x_mm_s", "velocity_y_mm_s"]].to_numpy()[0]
    goal = rotate((info["goal_mm"] - info["position_mm"])[None], np.array([-heading]))[0]
    np.testing.assert_allclose(observation[:2], goal, rtol=0, atol=1e-5)
    np.testing.assert_allclose(observation[4:6], rotate(velocity[None], np.array([-heading]))[0],
                               rtol=0, atol=1e-6)


def test_a_time_since_fired_past_its_cap_reads_the_cap():
    """Fired 50 ms ago with since_fired_cap_s = 0.02, A1 reads 0.02."""
    env = StarSwimmerEnv(**FAST, since_fired_cap_s=0.02)
    env.reset(seed=0)
    observation = env.step(ts.Gait.parse("A1").mask)[0]
    env.close()
    assert observation[7] == np.float32(0.02)
    np.testing.assert_array_equal(observation[8:], np.float32(0.02))


def test_vector_env_resets_and_steps_check_their_robots():
    """A later reset leaves an earlier info's distances as they were (a copy, not the
    batch's array); an integer reset_mask is refused; a robot never reset refuses the step,
    though the other robot was."""
    envs = StarSwimmerVectorEnv(2, **FAST)
    try:
        _, first = envs.reset(options={"goal": (10.0, 0.0)})
        envs.reset(options={"goal": (0.0, 20.0)})
        np.testing.assert_array_equal(first["distance_mm"], [10.0, 10.0])
        with pytest.raises(ValueError, match=re.escape("options['reset_mask'] must be a (2,) "
                                                       "bool array, got int64 (2,)")):
            envs.reset(options={"reset_mask": np.array([0, 1])})
    finally:
        envs.close()
    fresh = StarSwimmerVectorEnv(2, **FAST)
    try:
        fresh.reset(seed=0, options={"reset_mask": np.array([True, False])})
        with pytest.raises(RuntimeError, match=r"robot 1 has no episode yet"):
            fresh.step(np.zeros((2, 8), np.int8))
        assert fresh.simulator.time_s.tolist() == [0.0, 0.0]
    finally:
        fresh.close()


def test_an_sb3_seed_is_used_by_one_reset_only():
    """The reset after the seeded one draws new goals (the generators go on), as SB3's
    VecEnv.seed promises."""
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **FAST))
    try:
        adapter.seed(21)
        first = adapter.reset()
        second = adapter.reset()
        assert not np.array_equal(first[:, :2], second[:, :2])
        adapter.seed(21)
        np.testing.assert_array_equal(adapter.reset(), first)
    finally:
        adapter.close()


def test_the_observation_bounds_are_the_documented_ones():
    """Goal entries +-1e4 mm (10 m), sin/cos +-1, velocity +-1e3 mm/s, angular +-1e4 deg/s (a
    bound of 1e3 mm lived through the suite, clipping every goal past 1 m: a mutation audit,
    2026-12-07)."""
    env = StarSwimmerEnv(**SHORT)
    try:
        np.testing.assert_array_equal(env.observation_space.high[:7],
                                      [1e4, 1e4, 1.0, 1.0, 1e3, 1e3, 1e4])
    finally:
        env.close()


def test_the_firing_cost_is_paid_per_actuator_fired():
    """Two actuators fired at firing_cost_mm = 100 cost 200 mm of reward, not 100 (a cost per
    step that fired anything lived through the suite: a mutation audit, 2026-12-07); the
    progress of one 50-ms period is well under 1 mm."""
    env = StarSwimmerEnv(**SHORT, firing_cost_mm=100.0)
    try:
        env.reset(options={"goal": (30.0, 0.0)})
        _, reward, _, _, info = env.step(ts.Gait.parse("A1+A2").mask)
    finally:
        env.close()
    progress = 30.0 - info["distance_mm"]
    assert abs(progress) < 1.0
    assert reward == pytest.approx(progress - 200.0, abs=1e-9)


def test_the_heading_is_observed_as_its_sine_then_its_cosine():
    """OBSERVATION_NAMES: heading_sin, then heading_cos: (0, 1) at the start's heading 0 and
    the turned robot's sin/cos after a chiral firing (the two swapped lived through the suite:
    a mutation audit, 2026-12-07)."""
    env = StarSwimmerEnv(**SHORT)
    try:
        first, _ = env.reset(options={"goal": (30.0, 20.0)})
        np.testing.assert_array_equal(first[2:4], np.float32([0.0, 1.0]))
        observation, _, _, _, info = env.step(ts.Gait.parse("A1+A2+A4").mask)
    finally:
        env.close()
    heading = np.radians(info["heading_deg"])
    assert abs(heading) > 1e-5
    np.testing.assert_allclose(observation[2:4], [np.sin(heading), np.cos(heading)],
                               rtol=0, atol=1e-7)


def test_per_robot_scalar_goals_are_refused_not_read_as_one_point():
    """SB3 options of a number each, {"goal": 5.0} and {"goal": 7.0}, are refused by name
    (without the (2,) check they were stacked into the one goal (5, 7) of both robots: a
    mutation audit, 2026-12-07)."""
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **SHORT))
    try:
        adapter.set_options([{"goal": 5.0}, {"goal": 7.0}])
        with pytest.raises(ValueError, match=r"^set_options: the robots' options may differ "
                                             r"only in their goals"):
            adapter.reset()
    finally:
        adapter.close()


def test_sb3_infos_hold_no_masks_and_an_autoreset_updates_reset_infos():
    """The adapter's infos are the vector env's values row by row, without gymnasium's "_key"
    masks; a robot reset within a step has its new episode's reset info in `reset_infos`, as
    SB3's DummyVecEnv (the masks kept, or the first reset's infos kept, lived through the
    suite: a mutation audit, 2026-12-07)."""
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **SHORT, max_episode_steps=1))
    try:
        adapter.seed(3)
        adapter.reset()
        assert not any(key.startswith("_") for info in adapter.reset_infos for key in info)
        first_goals = [info["goal_mm"].copy() for info in adapter.reset_infos]
        _, _, dones, infos = adapter.step(np.zeros((2, 8), np.int8))
        assert dones.all()
        assert not any(key.startswith("_") for info in infos for key in info)
        for row in range(2):
            new_goal = adapter.envs.batch.goals[row]
            assert not np.array_equal(new_goal, first_goals[row])
            np.testing.assert_array_equal(adapter.reset_infos[row]["goal_mm"], new_goal)
            np.testing.assert_array_equal(infos[row]["goal_mm"], first_goals[row])
    finally:
        adapter.close()


def test_sb3_options_are_used_by_one_reset_only():
    """set_options' goal is the next reset's alone; the reset after draws goals at
    goal_distance_mm (options kept for every later reset, the goal (10, 0) each time, lived
    through the suite: a mutation audit, 2026-12-07)."""
    adapter = SB3VectorAdapter(StarSwimmerVectorEnv(2, **SHORT))
    try:
        adapter.set_options({"goal": (10.0, 0.0)})
        adapter.reset()
        np.testing.assert_array_equal(adapter.envs.batch.goals, [[10.0, 0.0], [10.0, 0.0]])
        adapter.reset()
        np.testing.assert_allclose(np.hypot(*adapter.envs.batch.goals.T), [50.0, 50.0])
    finally:
        adapter.close()


@pytest.mark.parametrize("speed, refused", [(None, False), (1000.0, False), (1e-9, False),
                                            (0.0, True), (-1.0, True), (float("nan"), True),
                                            (1000.5, True), ("1", True)])
def test_the_stop_speed_is_none_or_in_its_range(speed, refused):
    if refused:
        with pytest.raises(ValueError, match=r"^stop_speed_mm_s must be None or a number in "
                                             r"\(0, 1000\] mm/s"):
            SwimmerTask(stop_speed_mm_s=speed)
    else:
        assert SwimmerTask(stop_speed_mm_s=speed).stop_speed_mm_s == speed


@pytest.mark.parametrize("stop, ends", [(None, True), ("exact", True), ("below", False)])
def test_with_a_stop_speed_an_episode_ends_only_once_the_robot_is_that_slow(stop, ends):
    """A goal the robot reaches within the tolerance in one control period: without a stop
    speed the episode ends there; with one, only if the robot's speed then is at most it (the
    rule's boundary: its own speed, and the next number below)."""
    probe = StarSwimmerVectorEnv(1, **SHORT)
    probe.reset(options={"goal": (40.0, 0.0)})
    probe.step(FORWARD[None])
    state = probe.simulator.state()
    position = state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0]
    speed = float(np.hypot(*state[["velocity_x_mm_s", "velocity_y_mm_s"]].to_numpy()[0]))
    assert speed > 0.1  # still swimming at the period's end
    stop_speed = {None: None, "exact": speed, "below": np.nextafter(speed, 0.0)}[stop]
    env = StarSwimmerVectorEnv(1, **SHORT, goal_tolerance_mm=1.0, stop_speed_mm_s=stop_speed)
    env.reset(options={"goal": position})
    _, _, terminated, truncated, _ = env.step(FORWARD[None])
    assert terminated.tolist() == [ends] and truncated.tolist() == [False]


@pytest.mark.parametrize("settle, steps, refused", [
    (None, None, False), (1, None, False), (3, 4, False), (4, 4, True), (0, None, True),
    (-1, None, True), (1.5, None, True), (True, None, True), ("2", None, True)])
def test_the_settling_is_none_or_a_count_below_the_step_budget(settle, steps, refused):
    """settle_cycles: None or an integer >= 1, and below max_episode_steps where there is one
    (the boundary: budget - 1 allowed, the budget itself refused: no period left to fire)."""
    if refused:
        with pytest.raises(ValueError, match=r"^settle_cycles must be (an integer >= 1 or None"
                                             r"|below max_episode_steps \(4\))"):
            SwimmerTask(settle_cycles=settle, max_episode_steps=steps)
    else:
        assert SwimmerTask(settle_cycles=settle, max_episode_steps=steps).settle_cycles == settle


@pytest.mark.parametrize("budget, refused", [(None, True), (DEFAULT_MAX_EPISODE_STEPS + 1, False)])
def test_make_vec_checks_the_settling_against_the_budget_it_hands_over(budget, refused):
    """gymnasium.make_vec passes its step budget (the registered one unless given) to the
    vector env, whose task then refuses a settling as long as the budget (the boundary: the
    registered budget itself refused, one period more allowed), before any robot is built."""
    options = {} if budget is None else {"max_episode_steps": budget}
    if refused:
        with pytest.raises(ValueError, match=rf"^settle_cycles must be below max_episode_steps "
                                             rf"\({DEFAULT_MAX_EPISODE_STEPS}\)"):
            gym.make_vec(ENV_ID, num_envs=1, settle_cycles=DEFAULT_MAX_EPISODE_STEPS, **options)
    else:
        envs = gym.make_vec(ENV_ID, num_envs=1, settle_cycles=DEFAULT_MAX_EPISODE_STEPS, **options)
        try:
            assert envs.unwrapped.batch.task.settle_cycles == DEFAULT_MAX_EPISODE_STEPS
            assert envs.unwrapped.batch.task.max_episode_steps == budget
        finally:
            envs.close()


NONE = np.zeros(8, dtype=bool)


@pytest.mark.parametrize("settle, actions, ends", [
    (None, ["fire", "none", "none"], True), (2, ["fire", "none", "none"], True),
    (3, ["fire", "none", "none"], False), (2, ["fire", "none", "fire"], False),
    (1, ["fire", "fire", "none"], True), (2, ["fire", "fire", "none"], False)])
def test_with_a_settling_an_episode_ends_only_after_that_many_periods_unfired(settle, actions,
                                                                              ends):
    """The goal is where the robot is after the three periods of `actions` (reached there
    only): with settle_cycles the episode ends there only if the robot has fired nothing for
    that many periods (the boundary: exactly settle_cycles periods ends it, one fewer does
    not; a firing starts the count again)."""
    fire = {"fire": FORWARD, "none": NONE}
    probe = StarSwimmerVectorEnv(1, **SHORT)
    probe.reset(options={"goal": (40.0, 0.0)})
    positions = []
    for name in actions:
        probe.step(fire[name][None])
        state = probe.simulator.state()
        positions.append(state[["centroid_x_mm", "centroid_y_mm"]].to_numpy()[0])
    goal = positions[2]
    tolerance = 1e-6  # mm: reached at the third boundary only
    assert min(np.hypot(*(position - goal)) for position in positions[:2]) > 1e3 * tolerance
    env = StarSwimmerVectorEnv(1, **SHORT, goal_tolerance_mm=tolerance, settle_cycles=settle)
    env.reset(options={"goal": goal})
    said = []
    for name in actions:
        _, _, terminated, truncated, _ = env.step(fire[name][None])
        said.append((bool(terminated[0]), bool(truncated[0])))
    assert said == [(False, False), (False, False), (ends, False)]
