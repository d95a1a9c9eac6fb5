"""Auto-reset: start a new episode in the same slot when one ends, keeping what learners need.

Brax's own auto-reset wrapper returns every episode to one cached first state and folds
truncation into ``done``; this one draws each new start from the reset distribution with a
key carried in the state and keeps the terminated / truncated distinction.

``AutoReset.staggered_reset`` cuts the first episode at a random length, so that parallel
envs of a task that never terminates (HalfCheetah, Swimmer) do not stay in step: started
together and reset together at the time limit, every rollout of T steps would see the same
T-step window of the episode in every env.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax.envs.base import Env, EnvState


@struct.dataclass
class AutoResetState(EnvState):
    """An ``EnvState`` that also carries the observation the last step really reached.

    On the step that ends an episode, ``done`` / ``truncated`` / ``reward`` describe that
    final transition, ``final_obs`` is the final observation (use it to bootstrap a truncated
    episode's value), ``episode_return`` / ``episode_length`` are the finished episode's
    totals, and ``obs`` / ``internal`` already belong to the next episode's first state. On
    every other step ``final_obs == obs``.

    Attributes (beyond ``EnvState``'s):
      final_obs: float[observation_size].
      key: the PRNG key that draws the next reset.
      time_limit: int32[], the episode length at which the current episode is truncated:
        ``max_episode_steps``, except for a staggered first episode (``staggered_reset``).
    """

    final_obs: jax.Array
    key: jax.Array
    time_limit: jax.Array


class AutoReset(Env):
    """Wraps an ``Env`` so that a finished episode is followed by a fresh one.

    ``reset(key)`` and ``step(state, action)`` act on one environment, like the wrapped env;
    batch with ``jax.vmap``. Each reset after the first uses a new key split off the state's.
    """

    def __init__(self, env: Env):
        self.env = env
        self.name = env.name
        self.observation_size = env.observation_size
        self.action_size = env.action_size
        self.action_low = env.action_low
        self.action_high = env.action_high
        self.max_episode_steps = env.max_episode_steps

    def reset(self, key: jax.Array) -> AutoResetState:
        reset_key, carry_key = jax.random.split(key)
        state = self.env.reset(reset_key)
        return AutoResetState(
            **_fields(state),
            final_obs=state.obs,
            key=carry_key,
            time_limit=jnp.asarray(self.max_episode_steps, jnp.int32),
        )

    def staggered_reset(self, key: jax.Array, limit_key: jax.Array) -> AutoResetState:
        """``reset(key)`` whose first episode is truncated after a length drawn uniformly
        from 1 to ``max_episode_steps`` with ``limit_key``; every later episode runs its full
        time limit. Parallel envs started this way end their first episodes at different
        steps and stay out of step for the rest of the run (legged-robot codebases start each
        env at a random episode step for the same reason). The cut is a truncation, so a
        learner bootstraps through it as through the time limit, and ``ended_early`` tells
        it apart from a whole episode."""
        limit = jax.random.randint(limit_key, (), 1, self.max_episode_steps + 1, jnp.int32)
        return self.reset(key).replace(time_limit=limit)

    def ended_early(self, state: AutoResetState) -> jax.Array:
        """bool[]: the step that led to ``state`` cut an episode short, before it terminated or
        reached ``max_episode_steps`` (a staggered first episode): its ``episode_return`` is
        not a whole episode's."""
        return state.truncated & ~state.done & (state.episode_length < self.max_episode_steps)

    def step(self, state: AutoResetState, action: jax.Array) -> AutoResetState:
        # Counters restart where the previous step finished an episode: that state already
        # holds the next episode's first observation, but still the old episode's totals.
        previous_finished = state.done | state.truncated
        inner = EnvState(
            obs=state.obs,
            reward=state.reward,
            done=jnp.zeros_like(state.done),
            truncated=jnp.zeros_like(state.truncated),
            episode_return=jnp.where(previous_finished, 0, state.episode_return).astype(
                state.episode_return.dtype
            ),
            episode_length=jnp.where(previous_finished, 0, state.episode_length).astype(
                state.episode_length.dtype
            ),
            internal=state.internal,
        )
        stepped = self.env.step(inner, action)
        truncated = stepped.truncated | (stepped.episode_length >= state.time_limit)
        key, reset_key = jax.random.split(state.key)
        fresh = self.env.reset(reset_key)
        finished = stepped.done | truncated

        def pick(fresh_leaf, stepped_leaf):
            return jnp.where(finished, fresh_leaf, stepped_leaf)

        return AutoResetState(
            obs=pick(fresh.obs, stepped.obs),
            reward=stepped.reward,
            done=stepped.done,
            truncated=truncated,
            episode_return=stepped.episode_return,
            episode_length=stepped.episode_length,
            internal=jax.tree.map(pick, fresh.internal, stepped.internal),
            final_obs=stepped.obs,
            key=key,
            time_limit=jnp.where(
                finished, jnp.asarray(self.max_episode_steps, jnp.int32), state.time_limit
            ),
        )

    def _reset(self, key):  # pragma: no cover - reset is overridden
        raise AssertionError("AutoReset.reset is overridden")

    def _step(self, internal, action):  # pragma: no cover - step is overridden
        raise AssertionError("AutoReset.step is overridden")


def _fields(state: EnvState) -> dict:
    return {name: getattr(state, name) for name in EnvState.__dataclass_fields__}
