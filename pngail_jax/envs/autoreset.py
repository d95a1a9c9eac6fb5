"""Auto-reset: start a new episode in the same slot when one ends, keeping what learners need.

Brax's own auto-reset wrapper returns every episode to one cached first state and folds
truncation into ``done``; this one draws each new start from the reset distribution with a
key carried in the state and keeps the terminated / truncated distinction.
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
    """

    final_obs: jax.Array
    key: jax.Array


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
        return AutoResetState(**_fields(state), final_obs=state.obs, key=carry_key)

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
        key, reset_key = jax.random.split(state.key)
        fresh = self.env.reset(reset_key)
        finished = stepped.done | stepped.truncated

        def pick(fresh_leaf, stepped_leaf):
            return jnp.where(finished, fresh_leaf, stepped_leaf)

        return AutoResetState(
            obs=pick(fresh.obs, stepped.obs),
            reward=stepped.reward,
            done=stepped.done,
            truncated=stepped.truncated,
            episode_return=stepped.episode_return,
            episode_length=stepped.episode_length,
            internal=jax.tree.map(pick, fresh.internal, stepped.internal),
            final_obs=stepped.obs,
            key=key,
        )

    def _reset(self, key):  # pragma: no cover - reset is overridden
        raise AssertionError("AutoReset.reset is overridden")

    def _step(self, internal, action):  # pragma: no cover - step is overridden
        raise AssertionError("AutoReset.step is overridden")


def _fields(state: EnvState) -> dict:
    return {name: getattr(state, name) for name in EnvState.__dataclass_fields__}
