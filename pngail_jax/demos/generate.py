"""Rolling out policies into demonstrations, and labelling trajectories by their returns."""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax import envs


@struct.dataclass
class Episodes:
    """E whole episodes from the plain env: leaves [E, max_episode_steps, ...].

    ``valid`` marks steps taken before the episode terminated (all steps when it only
    truncates); ``returns`` float[E] sums the valid rewards.
    """

    observations: jax.Array
    actions: jax.Array
    rewards: jax.Array
    valid: jax.Array
    returns: jax.Array


def rollout_episodes(
    env: envs.Env, act: Callable[[jax.Array, jax.Array], jax.Array], keys: jax.Array
) -> Episodes:
    """Runs one episode per key. ``act(obs float[O], key) -> action float[A]``.

    Jittable; ``keys`` key[E] draw the start states and whatever randomness ``act`` uses.
    """

    def one(key):
        reset_key, act_key = jax.random.split(key)
        state = env.reset(reset_key)

        def body(carry, step_key):
            state, alive = carry
            action = act(state.obs, step_key)
            next_state = env.step(state, action)
            record = (state.obs, action, next_state.reward, alive)
            return (next_state, alive & ~next_state.done), record

        _, (obs, actions, rewards, valid) = jax.lax.scan(
            body, (state, jnp.ones((), bool)), jax.random.split(act_key, env.max_episode_steps)
        )
        return Episodes(
            observations=obs,
            actions=actions,
            rewards=rewards,
            valid=valid,
            returns=jnp.where(valid, rewards, 0.0).sum(),
        )

    return jax.vmap(one)(keys)


def uniform_random_actions(env: envs.Env):
    """``act`` drawing actions uniformly within the action bounds (the random policy)."""
    low, high = jnp.asarray(env.action_low), jnp.asarray(env.action_high)

    def act(obs, key):
        return jax.random.uniform(key, low.shape, minval=low, maxval=high)

    return act


def random_policy_return(env: envs.Env, key: jax.Array, num_episodes: int) -> float:
    """The mean return of ``num_episodes`` episodes of uniform random actions (the
    normalised return's 0), episode ``i`` drawn from ``split(key, num_episodes)[i]``."""
    keys = jax.random.split(key, num_episodes)
    episodes = jax.jit(lambda k: rollout_episodes(env, uniform_random_actions(env), k))(keys)
    return float(episodes.returns.mean())


def normalized_return(returns, random_return: float, optimal_return: float):
    """(R - R_random) / (R_optimal - R_random), the paper's normalisation."""
    return (np.asarray(returns) - random_return) / (optimal_return - random_return)
