"""gymnasium's -v4 tasks on MuJoCo Warp (``physics="warp"``, MJX's ``impl="warp"``), on the CPU.

Warp is an optional extra (``pip install "pngail-jax[warp]"``): without it these tests skip.
CI's heavy line (``.ci/run``) installs it and runs them. Warp compiles its CPU kernels with the
Clang it ships (no system compiler), once, into ``~/.cache/warp/<warp version>``
(``$WARP_CACHE_PATH`` moves it).

In float32 a whole episode cannot follow gymnasium's float64 one step for step, so the
comparison over whole episodes is per transition: from each state of gymnasium's episode, with
its action, one step of ours against gymnasium's; a trajectory of our own is compared over 50
steps only.

The tolerances are derived, not fitted. Warp computes in float32 and gymnasium's C engine in
float64, so the two part by float32 rounding (unit roundoff ``2**-24``, about 6e-8, of each
number) amplified by the dynamics over the steps compared: little on smooth tasks, by orders of
magnitude where a contact makes a step sensitive to its start. How far rounding alone moves the
steps compared is measured in gymnasium's engine itself (``_rounded_steps``): the same steps
replayed in float64 with qpos and qvel moved by one float32 rounding at unit scale
(``2**-24 x max(|x|, 1)``, random signs) at the start and after every substep. Each tolerance
is ``MARGIN`` (10) times that reach, computed by the test from the same states and actions
(about a second a task). The margin covers the rounding inside a float32 step (the contact
solver's above all), which moving the state does not model: Warp's differences measured
0.04-5.2 times the reach (2026-12-06, warp-lang 1.19 on the CPU; the closest, 5.2, Walker2d-v4's
99th percentile over transitions).

Ant-v4 is the exception: its steps part from gymnasium's by far more than rounding moves them
(largest observation difference 1.27, 99th percentile 0.043, reward 0.26, against a reach of
3.7e-5, 5.4e-6 and 0.065). MJX's JAX implementation in float64 gives the same numbers on the
same transitions (to 1e-6), and ``mjx.step`` alone on gymnasium's model the same 1.27, so this
is MJX's contact handling, which Warp shares: not rounding, not this library. Its tolerances
are a fit to those measurements, about 2.3 times each (``ENGINE_GAP``). (Ant's reward reach,
0.065, is no rounding either: gymnasium's Ant reads the torso's position from the kinematics of
the previous step's last substep, which lag qpos by one substep, while a step started from a
set state, ours or the replay, reads the current one.)
"""

import json

import gymnasium as gym
import jax
import mujoco
import numpy as np
import pytest
from test_gym_mujoco import _gymnasium_episode, _our_episode, sweep_resumes_bit_exactly

from pngail_jax import envs
from pngail_jax.envs.autoreset import AutoReset

pytest.importorskip("mujoco_warp", reason="MuJoCo Warp is an optional extra: pngail-jax[warp]")
pytestmark = pytest.mark.heavy  # Warp's kernels, and a MuJoCo model compile per test

EPISODE_STEPS = 1000
TASKS = ("Ant-v4", "HalfCheetah-v4", "Hopper-v4", "Swimmer-v4", "Walker2d-v4")
ROUNDOFF = 2.0**-24  # float32's unit roundoff: rounding moves a number by at most this, relative
MARGIN = 10
# (largest, 99th percentile, reward) fitted to Warp's measured 1.27, 0.043, 0.26 (module note).
ENGINE_GAP = {"Ant-v4": (3.0, 0.1, 0.6)}


def _rounded_steps(reference, qpos, qvel, actions, rng):
    """gymnasium's float64 ``reference`` stepped from ``(qpos, qvel)`` (no warm start, as ours
    starts) with ``actions``, qpos and qvel moved by one float32 rounding at unit scale at the
    start and after every substep: (observations, rewards) of each step."""
    model, data = reference.model, reference.data

    def round_state():
        for x in (data.qpos, data.qvel):
            x += ROUNDOFF * np.maximum(np.abs(x), 1.0) * rng.choice([-1.0, 1.0], x.shape)

    def substeps(ctrl, num_substeps):  # gymnasium's own, one mj_step at a time
        data.ctrl[:] = ctrl
        for _ in range(num_substeps):
            mujoco.mj_step(model, data)
            round_state()
        mujoco.mj_rnePostConstraint(model, data)

    # gymnasium's step computes the observation and reward around this call: they stay its own.
    reference._step_mujoco_simulation = substeps
    data.qacc_warmstart[:] = 0
    reference.set_state(qpos, qvel)
    round_state()
    mujoco.mj_forward(model, data)
    rows = [reference.step(action)[:2] for action in actions]
    return np.array([obs for obs, _ in rows]), np.array([reward for _, reward in rows])


def _rounding_reach(name, qpos, qvel, actions, obs, rewards, num_draws=4):
    """How far float32 rounding alone moves each transition (one step from each ``qpos[i]``,
    ``qvel[i]`` with ``actions[i]``) of gymnasium's float64 engine from its ``obs`` and
    ``rewards``: the largest difference of each entry over ``num_draws`` rounded replays, then
    (largest, 99th percentile) over the observation entries and the largest reward's."""
    reference = gym.make(name).unwrapped
    rng = np.random.default_rng(0)
    obs_reach, reward_reach = np.zeros_like(obs), np.zeros_like(rewards)
    for _ in range(num_draws):
        for index in range(len(qpos)):
            moved = _rounded_steps(
                reference, qpos[index], qvel[index], actions[index : index + 1], rng
            )
            obs_reach[index] = np.maximum(obs_reach[index], np.abs(moved[0][0] - obs[index]))
            reward_reach[index] = max(reward_reach[index], abs(moved[1][0] - rewards[index]))
    return obs_reach.max(), np.quantile(obs_reach, 0.99), reward_reach.max()


def _episode_rounding_reach(name, qpos, qvel, actions, obs, rewards, num_draws=9):
    """How far float32 rounding alone moves gymnasium's episode (``actions`` from ``qpos``,
    ``qvel``) from its ``obs`` and ``rewards``: the median over
    ``num_draws`` rounded replays of each replay's largest observation and reward difference.
    The median, not the largest: over 50 steps a rounding now and then flips a contact
    (Walker2d-v4: 12 replays in 200 moved by 0.31 at one step, the others by at most 6e-4)."""
    reference = gym.make(name).unwrapped
    rng = np.random.default_rng(0)
    largest = []
    for _ in range(num_draws):
        moved_obs, moved_rewards = _rounded_steps(reference, qpos, qvel, actions, rng)
        largest.append((np.abs(moved_obs - obs).max(), np.abs(moved_rewards - rewards).max()))
    return np.median(largest, axis=0)


def _gymnasium_transitions(name: str, seed: int):
    """Every transition of gymnasium's episodes over ``EPISODE_STEPS`` steps of uniform
    actions up to 1.2x the bounds, a new episode after a termination: (qpos, qvel) before
    the step, action, observation, reward, terminated."""
    reference = gym.make(name).unwrapped
    reference.reset(seed=seed)
    rng = np.random.default_rng(seed)
    low, high = reference.action_space.low, reference.action_space.high
    rows = []
    for _ in range(EPISODE_STEPS):
        qpos, qvel = reference.data.qpos.copy(), reference.data.qvel.copy()
        action = rng.uniform(1.2 * low, 1.2 * high)
        obs, reward, terminated, _, _ = reference.step(action)
        rows.append((qpos, qvel, action, obs, reward, terminated))
        if terminated:
            reference.reset(seed=int(rng.integers(2**30)))
    return [np.array(column) for column in zip(*rows, strict=True)]


def _transitions(env, qpos, qvel, actions):
    """One step of ``env`` from each (qpos, qvel) with its action, every transition at once."""

    def one(qpos, qvel, action):
        obs, internal = env.state_at(qpos, qvel)
        state = env.reset(jax.random.key(0)).replace(obs=obs, internal=internal)
        state = env.step(state, action)
        return state.obs, state.reward, state.done

    as32 = (np.asarray(x, np.float32) for x in (qpos, qvel, actions))
    return [np.asarray(x) for x in jax.jit(jax.vmap(one))(*as32)]


@pytest.mark.parametrize("name", TASKS)
def test_every_transition_of_whole_episodes_follows_gymnasium(name):
    """Largest and 99th-percentile observation difference and largest reward difference within
    ``MARGIN`` times rounding's reach (Ant-v4: ``ENGINE_GAP``); the same terminations. Reach
    (largest / p99 / reward), then Warp's differences, measured: Hopper-v4 1.3e-5 / 2.8e-6 /
    3.0e-5, 2.6e-6 / 1.2e-6 / 1.1e-6; Swimmer-v4 3.6e-5 / 3.7e-6 / 7.7e-6, 7.2e-6 / 2.1e-6 /
    4.2e-6; Walker2d-v4 8.8e-5 / 1.2e-5 / 3.0e-5, 2.0e-4 / 6.1e-5 / 1.0e-5; HalfCheetah-v4
    9.4e-3 / 9.7e-5 / 4.4e-5, 7.1e-3 / 4.6e-5 / 3.1e-5."""
    qpos, qvel, actions, obs, rewards, terminated = _gymnasium_transitions(name, 3)
    if name in ENGINE_GAP:
        largest, p99, reward_tolerance = ENGINE_GAP[name]
    else:
        reach = _rounding_reach(name, qpos, qvel, actions, obs, rewards)
        largest, p99, reward_tolerance = (MARGIN * value for value in reach)
    env = envs.make(name, physics="warp", warp_batch=len(qpos))
    our_obs, our_rewards, our_terminated = _transitions(env, qpos, qvel, actions)
    errors = np.abs(our_obs - obs)
    assert errors.max() <= largest, (errors.max(), largest)
    assert np.quantile(errors, 0.99) <= p99, (np.quantile(errors, 0.99), p99)
    reward_error = np.abs(our_rewards - rewards).max()
    assert reward_error <= reward_tolerance, (reward_error, reward_tolerance)
    np.testing.assert_array_equal(our_terminated, terminated)


@pytest.mark.parametrize("name", ["Hopper-v4", "Swimmer-v4", "Walker2d-v4"])
def test_the_first_50_steps_follow_gymnasium(name):
    """Stepped from its own states, as training runs it: observations and rewards within
    ``MARGIN`` times rounding's reach over the 50 steps (HalfCheetah and Ant part, as on MJX:
    docs/environments.md). Reach (observation / reward), then Warp's differences, measured:
    Hopper-v4 2.2e-5 / 3.2e-5, 5.4e-6 / 2.5e-6; Swimmer-v4 4.1e-6 / 7.6e-6, 7.6e-6 / 1.1e-6;
    Walker2d-v4 1.8e-4 / 3.4e-5, 1.2e-4 / 9.9e-6."""
    qpos, qvel, actions, obs, rewards, terminated = _gymnasium_episode(name, 3, num_steps=50)
    reach = _episode_rounding_reach(name, qpos, qvel, actions, obs, rewards)
    obs_tolerance, reward_tolerance = MARGIN * reach
    env = envs.make(name, physics="warp", warp_batch=1)
    our_obs, our_rewards, our_terminated = _our_episode(env, qpos, qvel, actions.astype(np.float32))
    np.testing.assert_allclose(our_obs, obs, rtol=0, atol=obs_tolerance)
    np.testing.assert_allclose(our_rewards, rewards, rtol=0, atol=reward_tolerance)
    np.testing.assert_array_equal(our_terminated, terminated)


def _rollout(env, keys, num_steps=120):
    """Auto-reset rollout of one env per key, random actions: (obs, reward, done)."""

    def run(key):
        def body(state, step_key):
            action = jax.random.uniform(step_key, (env.action_size,), minval=-1, maxval=1)
            state = env.step(state, action)
            return state, (state.obs, state.reward, state.done)

        state = env.reset(key)
        return jax.lax.scan(body, state, jax.random.split(jax.random.fold_in(key, 1), num_steps))[1]

    return [np.asarray(x) for x in jax.jit(jax.vmap(run))(keys)]


def test_a_batch_equals_its_envs_one_at_a_time_and_repeats_bit_identically():
    """Hopper-v4 (contacts and terminations) under AutoReset: four envs stepped together
    (one shared contact buffer) equal each stepped alone, bit for bit; the same keys give the
    same run."""
    keys = jax.random.split(jax.random.key(7), 4)
    batch = _rollout(AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=4)), keys)
    assert batch[2].any(), "no episode ended: the test would not cover auto-resets"
    again = _rollout(AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=4)), keys)
    alone_env = AutoReset(envs.make("Hopper-v4", physics="warp", warp_batch=1))
    for column, repeated in zip(batch, again, strict=True):
        np.testing.assert_array_equal(column, repeated)
    for index in range(len(keys)):
        alone = _rollout(alone_env, keys[index : index + 1])
        for column, single in zip(batch, alone, strict=True):
            np.testing.assert_array_equal(column[index], single[0])


def test_a_full_contact_buffer_gives_nan_not_a_wrong_step():
    """64 Hopper envs on a buffer sized for one (Warp's 48 contacts for Hopper): the steps
    that lost contacts say so."""
    keys = jax.random.split(jax.random.key(0), 64)
    obs, reward, _ = _rollout(envs.make("Hopper-v4", physics="warp", warp_batch=1), keys, 20)
    assert np.isnan(reward).any() and np.isnan(obs).any()
    sized = _rollout(envs.make("Hopper-v4", physics="warp", warp_batch=64), keys, 20)
    assert np.isfinite(sized[0]).all() and np.isfinite(sized[1]).all()


def test_bad_options_are_refused_in_one_line():
    with pytest.raises(ValueError, match="warp_batch must be a positive integer"):
        envs.make("Hopper-v4", physics="warp", warp_batch=0)
    with pytest.raises(ValueError, match="warp_batch is an option of physics='warp' only"):
        envs.make("Hopper-v4", physics="mjx", warp_batch=4)
    with pytest.raises(ValueError, match="observes contact forces"):
        envs.make("Ant-v5", physics="warp")


def test_sweep_on_warp_resumes_bit_exactly(tmp_path):
    whole = sweep_resumes_bit_exactly(tmp_path, "warp")
    assert json.loads((whole / "config.json").read_text())["resolved"]["physics"] == "warp"
