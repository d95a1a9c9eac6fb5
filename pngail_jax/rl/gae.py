"""Generalised advantage estimation over a fixed-length, auto-reset rollout.

GAE is the linear recurrence ``A_t = delta_t + c_t A_{t+1}`` (``c_t = gamma lam`` within an
episode, 0 across its end). ``form="sequential"`` runs it as a T-step ``lax.scan``;
``form="associative"`` composes the affine maps ``x -> delta_t + c_t x`` with
``lax.associative_scan``, a log2(T)-deep tree: the same numbers up to float rounding, with a
shorter chain of dependent steps (``benchmarks/iteration_phases.py`` times both).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from pngail_jax.config.learner import GAEForm


def generalized_advantages(
    rewards: jax.Array,
    values: jax.Array,
    next_values: jax.Array,
    done: jax.Array,
    truncated: jax.Array,
    gamma: float | jax.Array,
    lam: float | jax.Array,
    bootstrap_truncation: bool | jax.Array = True,
    form: GAEForm = "sequential",
) -> tuple[jax.Array, jax.Array]:
    """GAE(gamma, lambda) advantages and the matching value targets.

    Args:
      rewards, values: float[T, ...], r_t and V(s_t) along time (leading axis).
      next_values: float[T, ...], V of the state each step really reached (the auto-reset
        wrapper's ``final_obs``), so episode ends and the rollout's cut bootstrap correctly.
      done, truncated: bool[T, ...], termination and time-limit truncation of step t.
      lam: a scalar, or float[K] to get K advantage sets from one pass (leading axis K).
      bootstrap_truncation: if True (our default) a truncated, non-terminated step bootstraps
        from ``next_values``; if False truncation is treated as terminal (the reference's
        behaviour).
      form: ``"sequential"`` or ``"associative"`` (static), see the module docstring.

    Returns:
      ``(advantages, targets)``, float[T, ...] (float[K, T, ...] for a vector ``lam``):
      A_t = sum_k (gamma lam)^k delta_{t+k} within the episode, with
      delta_t = r_t + gamma (1 - terminal_t) V(s'_t) - V(s_t); targets are A_t + V(s_t)
      (with lam = 1: bootstrapped discounted returns).
    """
    if form not in ("sequential", "associative"):
        raise ValueError(f"GAE form must be 'sequential' or 'associative', got {form!r}")
    finished = done | truncated
    terminal = jnp.where(bootstrap_truncation, done, finished)
    deltas = rewards + gamma * jnp.where(terminal, 0.0, next_values) - values
    continues = 1.0 - finished.astype(rewards.dtype)
    lam = jnp.asarray(lam, rewards.dtype)
    # Decay per step, with one leading entry per lambda when lam is a vector.
    decay = gamma * lam.reshape(lam.shape + (1,) * continues.ndim) * continues
    deltas = jnp.broadcast_to(deltas, decay.shape)
    if lam.ndim:  # time leads inside the recurrence
        deltas, decay = jnp.moveaxis(deltas, lam.ndim, 0), jnp.moveaxis(decay, lam.ndim, 0)
    if form == "sequential":
        advantages = _sequential(deltas, decay)
    else:
        advantages = _associative(deltas, decay)
    if lam.ndim:
        advantages = jnp.moveaxis(advantages, 0, lam.ndim)
    return advantages, advantages + values


def _sequential(deltas: jax.Array, decay: jax.Array) -> jax.Array:
    def backward(next_advantage, inputs):
        delta, step_decay = inputs
        advantage = delta + step_decay * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(backward, jnp.zeros_like(deltas[0]), (deltas, decay), reverse=True)
    return advantages


def _associative(deltas: jax.Array, decay: jax.Array) -> jax.Array:
    # An element (c, d) is the map x -> d + c x from A_{t+1} to A_t. A reverse scan combines
    # the suffix already reduced (the later steps) with the earlier step:
    # earlier o later = x -> d_e + c_e (d_l + c_l x).
    def compose(later, earlier):
        later_decay, later_delta = later
        earlier_decay, earlier_delta = earlier
        return earlier_decay * later_decay, earlier_delta + earlier_decay * later_delta

    _, advantages = jax.lax.associative_scan(compose, (decay, deltas), reverse=True)
    return advantages
