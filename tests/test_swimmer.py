"""Our MJX Swimmer against gymnasium's Swimmer-v5 (C MuJoCo, float64) from identical states."""

import gymnasium as gym
import jax
import numpy as np
import pytest
from conftest import run_x64

from pngail_jax import envs

NUM_TRANSITIONS = 400


def _compiled(env):
    """Jitted ``step`` and a jitted ``state_at(qpos, qvel)`` (gymnasium's set_state)."""
    template = jax.jit(env.reset)(jax.random.key(0))  # only its structure is used
    data_from = jax.jit(env.data_from)

    def state_at(qpos, qvel):
        data = data_from(qpos, qvel)
        return template.replace(obs=env.observe(data), internal=data)

    return jax.jit(env.step), state_at


@pytest.fixture(scope="module")
def swimmer():
    env = envs.make("Swimmer")
    return (env, *_compiled(env))


def _gymnasium_run(seed, num_steps, action_limit):
    env = gym.make("Swimmer-v5")
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    data = env.unwrapped.data
    rows = []
    for _ in range(num_steps):
        action = rng.uniform(-action_limit, action_limit, size=2).astype(np.float32)
        qpos, qvel = data.qpos.copy(), data.qvel.copy()
        obs, reward, terminated, truncated, _ = env.step(action)
        assert not terminated
        rows.append((qpos, qvel, action, obs, reward))
    return [np.array(column) for column in zip(*rows, strict=True)]


def test_observation_and_spaces_match_gymnasium(swimmer):
    env, _, _ = swimmer
    reference = gym.make("Swimmer-v5")
    assert env.observation_size == reference.observation_space.shape[0] == 8
    np.testing.assert_array_equal(env.action_low, reference.action_space.low)
    np.testing.assert_array_equal(env.action_high, reference.action_space.high)
    assert env.max_episode_steps == reference.spec.max_episode_steps == 1000
    assert env.dt == pytest.approx(reference.unwrapped.dt)


def test_single_transitions_match(swimmer):
    """Transitions along a real trajectory, actions up to 1.5x the bounds (MuJoCo clamps)."""
    _, step, state_at = swimmer
    qpos, qvel, actions, expected_obs, expected_rewards = _gymnasium_run(
        seed=1, num_steps=NUM_TRANSITIONS, action_limit=1.5
    )
    obs, rewards = [], []
    for i in range(NUM_TRANSITIONS):
        next_state = step(state_at(qpos[i], qvel[i]), actions[i])
        obs.append(next_state.obs)
        rewards.append(next_state.reward)
    np.testing.assert_allclose(np.array(obs), expected_obs, rtol=0, atol=1e-5)
    np.testing.assert_allclose(np.array(rewards), expected_rewards, rtol=0, atol=1e-5)


def _trajectory(step, state_at, qpos0, qvel0, actions):
    state = state_at(qpos0, qvel0)
    obs, rewards = [], []
    for action in actions:
        state = step(state, action)
        obs.append(np.asarray(state.obs))
        rewards.append(np.asarray(state.reward))
    return np.array(obs), np.array(rewards)


def x64_trajectory_errors() -> dict:
    """Runs in a float64 subprocess: max |difference| over a 200-step trajectory."""
    assert jax.config.jax_enable_x64
    qpos, qvel, actions, expected_obs, expected_rewards = _gymnasium_run(
        seed=2, num_steps=200, action_limit=1.5
    )
    env = envs.make("Swimmer")
    obs, rewards = _trajectory(*_compiled(env), qpos[0], qvel[0], actions)
    assert obs.dtype == np.float64
    return {
        "obs": float(np.abs(obs - expected_obs).max()),
        "reward": float(np.abs(rewards - expected_rewards).max()),
    }


@pytest.mark.heavy
@pytest.mark.slow
def test_whole_trajectory_matches_under_x64():
    """200 steps from one state in float64: MJX and C MuJoCo agree to ~1e-13 here."""
    errors = run_x64(__file__, "x64_trajectory_errors")
    assert errors["obs"] < 1e-9 and errors["reward"] < 1e-9, errors


def test_float32_trajectory_drifts_slowly(swimmer):
    """In float32 the same 200 steps drift by rounding alone: measured here ~1e-6 by step 50,
    7e-6 by step 100 and 5e-5 by step 200."""
    _, step, state_at = swimmer
    qpos, qvel, actions, expected_obs, expected_rewards = _gymnasium_run(
        seed=2, num_steps=200, action_limit=1.5
    )
    obs, rewards = _trajectory(step, state_at, qpos[0], qvel[0], actions)
    obs_error = np.abs(obs - expected_obs).max(axis=1)
    assert obs_error[:50].max() < 1e-5, obs_error[:50].max()
    assert obs_error.max() < 2e-4, obs_error.max()
    np.testing.assert_allclose(rewards, expected_rewards, rtol=0, atol=2e-4)


def test_reset_distribution(swimmer):
    env, _, _ = swimmer
    states = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.key(0), 2000))
    qpos0 = np.asarray(gym.make("Swimmer-v5").unwrapped.init_qpos)
    qpos, qvel = np.asarray(states.internal.qpos), np.asarray(states.internal.qvel)
    for noise in (qpos - qpos0, qvel):
        assert np.abs(noise).max() <= 0.1
        np.testing.assert_allclose(noise.std(axis=0), 0.1 / np.sqrt(3), rtol=0.1)
    np.testing.assert_allclose(states.obs, np.concatenate([qpos[:, 2:], qvel], axis=1))
