"""Deterministic evaluation (returns counted up to termination, the early exit) and the
count of non-finite actions in rollouts."""

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


def test_nan_actions_are_counted_and_their_cell_reported():
    """A NaN observation makes the policy's action NaN; that action makes Pendulum's state
    NaN, so every later action of the episode is NaN too, until the time limit resets it.

    Slot 1 starts 2 steps before its 4-step limit with a NaN observation: steps 0 and 1
    apply NaN actions and step 1 truncates, so steps 2-4 run a fresh, finite episode.
    Count: 2 of the 2 x 5 steps.
    """
    from pngail_jax.grid import nonfinite_cells
    from pngail_jax.rl.rollout import collect, rollout_metrics

    env = envs.AutoReset(envs.make("Pendulum-v1", max_episode_steps=4))
    policy = GaussianPolicy(1, (4,))
    params = policy.init(jax.random.key(0), jnp.zeros(3))
    state = jax.vmap(env.reset)(jax.random.split(jax.random.key(1), 2))
    state = state.replace(
        obs=state.obs.at[1].set(jnp.nan), episode_length=state.episode_length.at[1].set(2)
    )

    def run(state):
        _, transitions = collect(env, policy, params, lambda obs: obs, state, 5, jax.random.key(2))
        return transitions, rollout_metrics(transitions)

    transitions, metrics = jax.jit(run)(state)
    finite_action = np.isfinite(transitions.action).all(axis=-1)  # [T, N]
    np.testing.assert_array_equal(finite_action[:, 0], True)
    np.testing.assert_array_equal(finite_action[:, 1], [False, False, True, True, True])
    np.testing.assert_array_equal(np.isfinite(transitions.reward[:, 1]), finite_action[:, 1])
    assert int(metrics["rollout/nonfinite_actions"]) == 2

    # Two cells of a one-iteration grid whose returns and losses are all finite: the count
    # alone reports cell 1.
    grid_metrics = {
        "eval/return": np.array([[-900.0], [-800.0]]),
        "disc/loss": np.array([[1.4], [1.3]]),
        "rollout/nonfinite_actions": np.array([[0], [int(metrics["rollout/nonfinite_actions"])]]),
    }
    assert nonfinite_cells(grid_metrics, eval_every=1).tolist() == [1]
    # A TRPO-only grid has no discriminator loss; metrics saved before the count have none.
    del grid_metrics["disc/loss"]
    assert nonfinite_cells(grid_metrics, eval_every=1).tolist() == [1]
    del grid_metrics["rollout/nonfinite_actions"]
    assert nonfinite_cells(grid_metrics, eval_every=1).tolist() == []
