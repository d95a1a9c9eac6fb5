"""The functional environment API every part of pngail-jax uses.

An environment is a plain Python object holding static information (sizes, bounds, the
physics model); its state is a pytree. ``reset`` and ``step`` are pure functions of their
arguments, so they can be jitted, vmapped across parallel environments and scanned over time.
Both act on one environment: batch them with ``jax.vmap``.

``step`` never resets. After the last step of an episode ``obs`` is the true final observation
and ``done`` (terminated) or ``truncated`` (time limit) is True; ``envs.AutoReset`` starts the
next episode.
"""

from __future__ import annotations

import abc
import math
import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class EnvState:
    """State of one environment after a reset or a step.

    Attributes:
      obs: float[observation_size], the observation reached.
      reward: float[], reward of the transition that led here (0 after a reset).
      done: bool[], the episode terminated (a true terminal state: do not bootstrap).
      truncated: bool[], the episode hit ``max_episode_steps``. As in gymnasium, both flags
        may be True on the same step; a learner should bootstrap only when
        ``truncated & ~done``.
      episode_return: float[], sum of rewards of the current episode so far.
      episode_length: int32[], steps taken in the current episode so far.
      internal: environment-specific pytree (angles, physics data, ...).
    """

    obs: jax.Array
    reward: jax.Array
    done: jax.Array
    truncated: jax.Array
    episode_return: jax.Array
    episode_length: jax.Array
    internal: Any


class Env(abc.ABC):
    """Base class of all environments: static attributes plus pure ``reset`` and ``step``.

    Subclasses set the attributes below in ``__init__`` and implement ``_reset`` and
    ``_step``; the public methods add input checks and the episode bookkeeping. Constructors
    check their options before building anything (``check_positive_int``,
    ``check_positive_finite``), so a bad option fails at once with a message naming it.

    Attributes:
      name: the registry name (``"Pendulum-v1"``, ``"Hopper"``, ...).
      observation_size: length of ``obs``.
      action_size: length of an action.
      action_low, action_high: float32[action_size] NumPy arrays, the action bounds. Actions
        outside them are accepted; each environment documents how it treats them.
      max_episode_steps: the time limit that sets ``truncated``.
    """

    name: str
    observation_size: int
    action_size: int
    action_low: np.ndarray
    action_high: np.ndarray
    max_episode_steps: int

    def reset(self, key: jax.Array) -> EnvState:
        """Draws an initial state from the reset distribution. ``key``: one PRNG key."""
        obs, internal = self._reset(key)
        zero = jnp.zeros((), obs.dtype)
        return EnvState(
            obs=obs,
            reward=zero,
            done=jnp.zeros((), bool),
            truncated=jnp.zeros((), bool),
            episode_return=zero,
            episode_length=jnp.zeros((), jnp.int32),
            internal=internal,
        )

    def step(self, state: EnvState, action: jax.Array) -> EnvState:
        """Advances one environment by one step. ``action``: float[action_size].

        The action's shape and dtype are checked when traced; its values cannot be (they are
        traced), so a NaN or inf action is applied as given. As in gymnasium's Pendulum-v1,
        it makes the reward and the state non-finite, and they stay so until the episode
        ends (at the time limit, or at once where a health check fails on NaN, as in Brax's
        Hopper); ``AutoReset`` then starts a finite one. Rollouts count such steps
        (``rollout/nonfinite_actions``, ``pngail_jax.rl.rollout.rollout_metrics``) and
        ``pngail_jax.grid.nonfinite_cells`` reports the runs that had any.
        """
        action = check_action(self, action)
        obs, reward, terminated, internal = self._step(state.internal, action)
        episode_length = state.episode_length + 1
        return EnvState(
            obs=obs,
            reward=reward,
            done=jnp.asarray(terminated, bool),
            truncated=episode_length >= self.max_episode_steps,
            episode_return=state.episode_return + reward,
            episode_length=episode_length,
            internal=internal,
        )

    @abc.abstractmethod
    def _reset(self, key: jax.Array) -> tuple[jax.Array, Any]:
        """Returns ``(obs, internal)`` of a fresh episode."""

    @abc.abstractmethod
    def _step(self, internal: Any, action: jax.Array) -> tuple[jax.Array, jax.Array, Any, Any]:
        """Returns ``(obs, reward, terminated, internal)`` after applying ``action``."""

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}(name={self.name!r}, observation_size={self.observation_size}"
            f", action_size={self.action_size}, max_episode_steps={self.max_episode_steps})"
        )


def check_action(env: Env, action: Any) -> jax.Array:
    """Returns ``action`` as a float array of shape ``(env.action_size,)``, or raises.

    Runs at trace time (shapes and dtypes are static), so a wrong action fails with a
    message naming the problem instead of a broadcasting error deep inside the physics.
    """
    action = jnp.asarray(action)
    if action.shape != (env.action_size,):
        hint = ""
        if action.ndim > 1 or (action.ndim == 1 and action.shape[0] % env.action_size == 0):
            hint = " (step acts on one environment: batch with jax.vmap(env.step))"
        raise ValueError(
            f"{env.name}: action must have shape ({env.action_size},), got {action.shape}{hint}"
        )
    if jnp.issubdtype(action.dtype, jnp.integer):
        return action.astype(float_dtype())
    if not jnp.issubdtype(action.dtype, jnp.floating):
        raise TypeError(f"{env.name}: action must be a real number array, got dtype {action.dtype}")
    # Float actions keep their width, as in gymnasium: a float32 action applied to a float64
    # state is combined with NumPy's (and JAX's) promotion rules, so the x64 equality holds.
    return action


def check_positive_int(env_name: str, option: str, value: Any) -> int:
    """``value`` as an ``int``, or a ValueError naming the option and the value: counts such as
    ``max_episode_steps`` must be integers >= 1 (a bool or an integral float is refused, as
    it is more likely a mistake than a count)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ValueError(f"{env_name}: {option} must be a positive integer, got {value!r}")
    return int(value)


def check_positive_finite(env_name: str, option: str, value: Any) -> float:
    """``value`` as a ``float``, or a ValueError naming the option and the value: physical
    constants such as gravity must be finite real numbers > 0."""
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Real)
        or not math.isfinite(value)
        or value <= 0
    ):
        raise ValueError(f"{env_name}: {option} must be a finite number > 0, got {value!r}")
    return float(value)


def float_dtype() -> jnp.dtype:
    """The float width JAX is set to now: float64 under ``jax_enable_x64``, else float32."""
    return jnp.result_type(float)
