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
        return transitions, rollout_metrics(transitions, env)

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


def _staggered_rollout(num_envs: int, max_episode_steps: int, unroll_length: int, key):
    """Countdown envs that never terminate, started by ``staggered_reset``, rolled out."""
    from pngail_jax.rl.rollout import collect

    env = envs.AutoReset(Countdown(5, max_episode_steps, never_terminates=True))
    policy = GaussianPolicy(1, (4,))
    params = policy.init(jax.random.key(0), jnp.zeros(1))
    reset_key, limit_key, rollout_key = jax.random.split(key, 3)
    state = jax.vmap(env.staggered_reset)(
        jax.random.split(reset_key, num_envs), jax.random.split(limit_key, num_envs)
    )
    limits = np.asarray(state.time_limit)
    _, transitions = jax.jit(
        lambda s: collect(env, policy, params, lambda obs: obs, s, unroll_length, rollout_key)
    )(state)
    return limits, transitions


def test_staggered_starts_cut_the_first_episode_and_keep_envs_out_of_step():
    """Each env's first episode ends after its drawn limit (uniform on 1..max), every later
    one after max steps; so env n's episodes end at steps limit_n + k * max, and envs with
    different limits never reset together. Only the first cut is ``ended_early``."""
    max_steps, unroll = 10, 45
    limits, transitions = _staggered_rollout(64, max_steps, unroll, jax.random.key(3))
    assert limits.min() >= 1 and limits.max() <= max_steps
    assert len(set(limits.tolist())) >= 8  # 64 draws from 10 values: nearly all appear
    truncated = np.asarray(transitions.truncated)  # [T, N]
    ended_early = np.asarray(transitions.ended_early)
    assert not np.asarray(transitions.done).any()
    for n, limit in enumerate(limits):
        ends = np.flatnonzero(truncated[:, n]) + 1  # episode ends, as step counts
        np.testing.assert_array_equal(ends, np.arange(limit, unroll + 1, max_steps))
        # the first episode's return is its own length (reward 1 per step), not max's
        assert transitions.episode_return[ends[0] - 1, n] == limit
        np.testing.assert_array_equal(
            np.flatnonzero(ended_early[:, n]) + 1, [limit] if limit < max_steps else []
        )
    # The envs' episodes are out of step: at any step, envs with different limits are at
    # different points of their episodes, so no single step truncates them all.
    assert truncated.sum(axis=1).max() < 64 / 4


def test_training_returns_count_whole_episodes_only():
    """A staggered first episode cut short is left out of ``train/episode_return``; a whole
    one (here: every later episode, max steps of reward 1) is counted."""
    from pngail_jax.rl.on_policy import episode_metrics

    max_steps = 10
    limits, transitions = _staggered_rollout(8, max_steps, 8, jax.random.key(4))
    # 8 steps: only first episodes can end, and all of them end early (or not at all)
    metrics = episode_metrics(transitions, transitions.reward)
    assert (limits <= 8).any()
    assert np.isnan(metrics["train/episode_return"])
    limits, transitions = _staggered_rollout(8, max_steps, 25, jax.random.key(4))
    metrics = episode_metrics(transitions, transitions.reward)
    assert float(metrics["train/episode_return"]) == max_steps


def test_rollout_metrics_of_the_actions_against_numpy():
    """Mean |a| and the share of entries outside the bounds, over every entry, on hand-made
    actions of a 2-D action space with bounds [-1, 1] and [-2, 0.5]."""
    from pngail_jax.rl.rollout import Transitions, rollout_metrics

    class Bounds:
        action_low = np.array([-1.0, -2.0], np.float32)
        action_high = np.array([1.0, 0.5], np.float32)

    actions = np.random.default_rng(0).normal(0, 1.5, (7, 3, 2)).astype(np.float32)
    actions[0, 0] = [1.0, 0.5]  # on the bounds: inside
    zeros = np.zeros((7, 3), np.float32)
    transitions = Transitions(
        obs=zeros[..., None], action=actions, log_prob=zeros, reward=zeros, done=zeros > 0,
        truncated=zeros > 0, final_obs=zeros[..., None], episode_return=zeros,
        ended_early=zeros > 0,
    )  # fmt: skip
    metrics = rollout_metrics(transitions, Bounds())
    beyond = (actions < Bounds.action_low) | (actions > Bounds.action_high)
    assert not beyond[0, 0].any()
    np.testing.assert_allclose(metrics["rollout/mean_abs_action"], np.abs(actions).mean(), 1e-6)
    np.testing.assert_allclose(metrics["rollout/beyond_bounds"], beyond.mean(), 1e-6)
    assert 0 < beyond.mean() < 1
    assert int(metrics["rollout/nonfinite_actions"]) == 0
