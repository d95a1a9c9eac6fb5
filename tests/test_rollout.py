"""Deterministic evaluation: returns counted up to termination, and the early exit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax import envs
from pngail_jax.envs.base import Env
from pngail_jax.networks import GaussianPolicy
from pngail_jax.rl.rollout import evaluate, evaluate_episodes


class Countdown(Env):
    """Reward 1 per step; terminates after a length drawn at reset from 1..max_length (or
    never, when ``never_terminates``). Actions are ignored."""

    def __init__(self, max_length: int, max_episode_steps: int, never_terminates=False):
        self.name = "Countdown"
        self.observation_size = 1
        self.action_size = 1
        self.action_low = np.full(1, -1.0, np.float32)
        self.action_high = np.full(1, 1.0, np.float32)
        self.max_episode_steps = max_episode_steps
        self.max_length = max_length
        self.never_terminates = never_terminates

    def length(self, key):
        return jax.random.randint(key, (), 1, self.max_length + 1)

    def _reset(self, key):
        remaining = self.length(key)
        return remaining[None].astype(jnp.float32), remaining

    def _step(self, remaining, action):
        remaining = remaining - 1
        terminated = (remaining <= 0) & (not self.never_terminates)
        return remaining[None].astype(jnp.float32), jnp.float32(1.0), terminated, remaining


@pytest.fixture(scope="module")
def policy_inputs():
    policy = GaussianPolicy(1, (4,))
    params = policy.init(jax.random.key(0), jnp.zeros(1))
    keys = jax.random.split(jax.random.key(1), 6)
    return policy, params, keys


def test_returns_stop_at_termination_and_the_loop_at_the_last_one(policy_inputs):
    policy, params, keys = policy_inputs
    env = Countdown(max_length=30, max_episode_steps=100)
    returns, num_steps = evaluate_episodes(env, policy, params, lambda obs: obs, keys)
    lengths = np.asarray(jax.vmap(env.length)(keys))  # reset draws them from these keys
    np.testing.assert_array_equal(returns, lengths)
    assert int(num_steps) == lengths.max() < env.max_episode_steps
    mean = evaluate(env, policy, params, lambda obs: obs, keys)
    np.testing.assert_allclose(mean, lengths.mean(), rtol=1e-6)


def test_time_limit_caps_episodes_that_never_end(policy_inputs):
    policy, params, keys = policy_inputs
    env = Countdown(max_length=30, max_episode_steps=12, never_terminates=True)
    returns, num_steps = evaluate_episodes(env, policy, params, lambda obs: obs, keys)
    np.testing.assert_array_equal(returns, 12.0)
    assert int(num_steps) == 12


def test_vmapped_runs_wait_for_the_slowest_and_keep_their_own_returns(policy_inputs):
    policy, params, keys = policy_inputs
    env = Countdown(max_length=30, max_episode_steps=100)
    run = jax.vmap(lambda k: evaluate_episodes(env, policy, params, lambda obs: obs, k))
    batched_returns, steps = run(jnp.stack([keys, keys[::-1]]))
    alone, _ = evaluate_episodes(env, policy, params, lambda obs: obs, keys)
    np.testing.assert_array_equal(batched_returns[0], alone)
    np.testing.assert_array_equal(batched_returns[1], np.asarray(alone)[::-1])
    assert int(steps[0]) == int(steps[1]) == int(np.max(alone))


def test_pendulum_runs_its_full_time_limit(policy_inputs):
    _, _, keys = policy_inputs
    env = envs.make("Pendulum-v1", max_episode_steps=7)
    policy = GaussianPolicy(1, (4,))
    params = policy.init(jax.random.key(0), jnp.zeros(3))
    _, num_steps = evaluate_episodes(env, policy, params, lambda obs: obs, keys)
    assert int(num_steps) == 7
