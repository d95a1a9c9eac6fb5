"""Fixed-shape rollouts from parallel auto-reset environments, and deterministic evaluation."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax import envs
from pngail_jax.networks import GaussianPolicy, gaussian_log_prob


@struct.dataclass
class Transitions:
    """One iteration's experience, time-major: leaves are [T, N, ...].

    obs and final_obs are raw (unnormalised) observations: obs is where the action was taken,
    final_obs where the step really arrived (before any auto-reset). ``ended_early`` marks the
    steps that cut a staggered first episode short (``envs.AutoReset.staggered_reset``):
    they are truncations, but their ``episode_return`` is not a whole episode's.
    """

    obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    reward: jax.Array
    done: jax.Array
    truncated: jax.Array
    final_obs: jax.Array
    episode_return: jax.Array
    ended_early: jax.Array


def collect(
    env: envs.AutoReset,
    policy: GaussianPolicy,
    policy_params,
    normalize: Callable[[jax.Array], jax.Array],
    env_state: envs.AutoResetState,
    unroll_length: int,
    key: jax.Array,
) -> tuple[envs.AutoResetState, Transitions]:
    """Steps N parallel envs (``env_state`` leaves are [N, ...]) ``unroll_length`` times.

    Actions are sampled from the Gaussian policy and passed unclipped (the environment
    clips, as the reference does), non-finite ones included: ``rollout_metrics`` counts
    those.
    """
    step = jax.vmap(env.step)

    def body(env_state, step_key):
        mean, log_std = policy.apply(policy_params, normalize(env_state.obs))
        noise = jax.random.normal(step_key, mean.shape, mean.dtype)
        action = mean + jnp.exp(log_std) * noise
        next_state = step(env_state, action)
        transition = Transitions(
            obs=env_state.obs,
            action=action,
            log_prob=gaussian_log_prob(mean, log_std, action),
            reward=next_state.reward,
            done=next_state.done,
            truncated=next_state.truncated,
            final_obs=next_state.final_obs,
            episode_return=next_state.episode_return,
            ended_early=env.ended_early(next_state),
        )
        return next_state, transition

    return jax.lax.scan(body, env_state, jax.random.split(key, unroll_length))


def rollout_metrics(transitions: Transitions, env: envs.Env) -> dict[str, jax.Array]:
    """Health of one iteration's rollout, added to the training metrics of every trainer.

    ``rollout/nonfinite_actions``: int32[], how many of the T * N steps applied an action
    with a NaN or inf entry. The environment takes such an action as it is and its state
    turns non-finite for the rest of the episode (``Env.step``); the count names that cause
    in the run's own metrics, whatever the learner makes of the NaN rewards that follow, and
    ``pngail_jax.grid.nonfinite_cells`` reports every run with a nonzero count.

    ``rollout/mean_abs_action``: float[], the mean |a| over every entry of the sampled
    actions; ``rollout/beyond_bounds``: float[], the share of those entries outside
    ``[env.action_low, env.action_high]`` (the environment clips them, the discriminator sees
    them clipped). Per entry, not per action: with a unit Gaussian on HalfCheetah's six
    joints 90% of actions have some entry beyond +-1, 32% of entries do. A policy whose
    Gaussian drifts past its bounds shows here long before its return says why.
    """
    action = transitions.action
    finite = jnp.isfinite(action).all(axis=-1)
    beyond = (action < env.action_low) | (action > env.action_high)
    return {
        "rollout/nonfinite_actions": jnp.sum(~finite, dtype=jnp.int32),
        "rollout/mean_abs_action": jnp.mean(jnp.abs(action)),
        "rollout/beyond_bounds": jnp.mean(beyond),
    }


def evaluate(
    env: envs.Env,
    policy: GaussianPolicy,
    policy_params,
    normalize: Callable[[jax.Array], jax.Array],
    keys: jax.Array,
) -> jax.Array:
    """Mean undiscounted return of the deterministic (mean-action) policy: the mean of
    ``evaluate_episodes``' returns."""
    returns, _ = evaluate_episodes(env, policy, policy_params, normalize, keys)
    return returns.mean()


def evaluate_episodes(
    env: envs.Env,
    policy: GaussianPolicy,
    policy_params,
    normalize: Callable[[jax.Array], jax.Array],
    keys: jax.Array,
) -> tuple[jax.Array, jax.Array]:
    """Undiscounted returns float[E] of the deterministic policy, one episode per key in
    ``keys`` (key[E]), and the number of steps the loop ran (int[]).

    The episodes run in parallel on the plain env for at most ``max_episode_steps`` steps;
    rewards after an episode's termination are not counted. The loop stops as soon as every
    episode has terminated (under ``vmap`` over runs: once every run's episodes have), so a
    policy that falls early costs only the steps it lives.
    """
    states = jax.vmap(env.reset)(keys)
    step = jax.vmap(env.step)

    def running(carry):
        _, _, alive, steps = carry
        return (steps < env.max_episode_steps) & alive.any()

    def body(carry):
        states, returns, alive, steps = carry
        mean, _ = policy.apply(policy_params, normalize(states.obs))
        states = step(states, mean)
        returns = returns + jnp.where(alive, states.reward, 0.0)
        return states, returns, alive & ~states.done, steps + 1

    num_episodes = keys.shape[0]
    initial = (states, jnp.zeros(num_episodes), jnp.ones(num_episodes, bool), jnp.zeros((), int))
    _, returns, _, num_steps = jax.lax.while_loop(running, body, initial)
    return returns, num_steps
