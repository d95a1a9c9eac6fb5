"""Our Pendulum-v1 against gymnasium's own, from identical states and actions."""

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import run_x64

from pngail_jax import envs
from pngail_jax.envs.pendulum import PendulumInternal

NUM_EPISODES = 6  # 6 x 200 = 1,200 transitions


def _gymnasium_episodes(seed: int, num_episodes: int, round_states_to_float32: bool):
    """Real gymnasium trajectories under random torques, 50% beyond the +-2 bound.

    With ``round_states_to_float32``, the state is rounded to float32 values before each
    step, so the float32 test starts both implementations from exactly the same state
    (rounding only our copy would test the float32 quantisation of theta, which grows to tens
    of radians, rather than the dynamics).
    """
    env = gym.make("Pendulum-v1")
    rng = np.random.default_rng(seed)
    episodes = []
    for episode in range(num_episodes):
        env.reset(seed=seed + episode)
        start = env.unwrapped.state.copy()
        states, actions, next_obs, rewards, truncations = [], [], [], [], []
        for _ in range(200):
            action = rng.uniform(-3.0, 3.0, size=(1,)).astype(np.float32)
            if round_states_to_float32:
                env.unwrapped.state = env.unwrapped.state.astype(np.float32).astype(np.float64)
            states.append(env.unwrapped.state.copy())
            obs, reward, terminated, truncated, _ = env.step(action)
            assert not terminated
            actions.append(action)
            next_obs.append(obs)
            rewards.append(reward)
            truncations.append(truncated)
        episodes.append(
            dict(
                start=start,
                states=np.array(states),
                actions=np.array(actions),
                next_obs=np.array(next_obs),
                rewards=np.array(rewards),
                truncated=np.array(truncations),
            )
        )
    return episodes


@pytest.fixture(scope="module")
def episodes():
    return _gymnasium_episodes(seed=0, num_episodes=NUM_EPISODES, round_states_to_float32=False)


def test_single_transitions_match_float32():
    episodes = _gymnasium_episodes(
        seed=100, num_episodes=NUM_EPISODES, round_states_to_float32=True
    )
    env = envs.make("Pendulum-v1")
    states = np.concatenate([e["states"] for e in episodes]).astype(np.float32)
    actions = np.concatenate([e["actions"] for e in episodes])
    expected_obs = np.concatenate([e["next_obs"] for e in episodes])
    expected_rewards = np.concatenate([e["rewards"] for e in episodes])
    assert len(states) >= 1000 and np.abs(actions).max() > 2.0

    def one(state, action):
        env_state = env.reset(jax.random.key(0))  # replaced below: only the structure is used
        env_state = env_state.replace(internal=PendulumInternal(theta=state[0], theta_dot=state[1]))
        return env.step(env_state, action)

    out = jax.jit(jax.vmap(one))(jnp.asarray(states), jnp.asarray(actions))
    assert out.obs.dtype == jnp.float32
    np.testing.assert_allclose(out.obs, expected_obs, rtol=0, atol=1e-5)
    # float32 costs up to 16 from angles of tens of radians: each rounding is 1e-6 to 2e-6
    # (up to 8.6e-6 seen from other seeds' states against gymnasium's float64): atol 3e-5.
    np.testing.assert_allclose(out.reward, expected_rewards, rtol=0, atol=3e-5)


def x64_episode_errors() -> dict:
    """Runs in a float64 subprocess: max |difference| over whole 200-step episodes."""
    assert jax.config.jax_enable_x64
    episodes = _gymnasium_episodes(seed=0, num_episodes=NUM_EPISODES, round_states_to_float32=False)
    env = envs.make("Pendulum-v1")

    def episode(start, actions):
        state = env.reset(jax.random.key(0))
        state = state.replace(internal=PendulumInternal(theta=start[0], theta_dot=start[1]))
        return jax.lax.scan(lambda s, a: (env.step(s, a),) * 2, state, actions)[1]

    starts = jnp.asarray(np.stack([e["start"] for e in episodes]), jnp.float64)
    # float32 actions, as gymnasium got them: its torque terms are computed in float32.
    actions = jnp.asarray(np.stack([e["actions"] for e in episodes]))
    trace = jax.jit(jax.vmap(episode))(starts, actions)
    assert trace.obs.dtype == jnp.float64
    expected_truncated = np.stack([e["truncated"] for e in episodes])
    return {
        "obs": float(np.abs(trace.obs - np.stack([e["next_obs"] for e in episodes])).max()),
        "reward": float(np.abs(trace.reward - np.stack([e["rewards"] for e in episodes])).max()),
        # gymnasium's TimeLimit truncates at step 200, and so must we.
        "truncation_mismatches": int((np.asarray(trace.truncated) != expected_truncated).sum()),
        "truncations": int(expected_truncated.sum()),
    }


def test_whole_episodes_match_under_x64():
    """Measured here: 2.4e-7 after 200 chaotic steps (1e-16 differences in sin grow)."""
    errors = run_x64(__file__, "x64_episode_errors")
    assert errors["obs"] < 1e-5 and errors["reward"] < 1e-5, errors
    assert errors["truncations"] == NUM_EPISODES and errors["truncation_mismatches"] == 0


def test_float32_episodes_drift_only_by_chaos(episodes):
    """In float32 the same episodes drift (chaotic dynamics) but stay close early on."""
    env = envs.make("Pendulum-v1")
    start, actions = episodes[0]["start"], episodes[0]["actions"]
    state = env.reset(jax.random.key(0))
    state = state.replace(
        internal=PendulumInternal(theta=jnp.float32(start[0]), theta_dot=jnp.float32(start[1]))
    )
    trace = jax.jit(lambda s, a: jax.lax.scan(lambda s, a: (env.step(s, a),) * 2, s, a)[1])(
        state, jnp.asarray(actions)
    )
    np.testing.assert_allclose(trace.obs[:20], episodes[0]["next_obs"][:20], atol=1e-4)


def test_reset_distribution():
    env = envs.make("Pendulum-v1")
    states = jax.vmap(env.reset)(jax.random.split(jax.random.key(0), 20_000))
    theta, theta_dot = np.asarray(states.internal.theta), np.asarray(states.internal.theta_dot)
    assert np.all(np.abs(theta) <= np.pi) and np.all(np.abs(theta_dot) <= 1.0)
    # U(-a, a): mean 0, standard deviation a / sqrt(3); 5-sigma bands for 20,000 draws.
    for values, half_width in ((theta, np.pi), (theta_dot, 1.0)):
        std = half_width / np.sqrt(3)
        assert abs(values.mean()) < 5 * std / np.sqrt(len(values))
        assert abs(values.std() - std) < 0.02 * std
    np.testing.assert_allclose(states.obs[:, 0], np.cos(theta), atol=1e-6)
    np.testing.assert_allclose(states.obs[:, 1], np.sin(theta), atol=1e-6)
    np.testing.assert_array_equal(states.obs[:, 2], theta_dot)
    assert not states.done.any() and not states.truncated.any()
    assert (states.episode_length == 0).all()
