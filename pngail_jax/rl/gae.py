"""Generalised advantage estimation over a fixed-length, auto-reset rollout."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def generalized_advantages(
    rewards: jax.Array,
    values: jax.Array,
    next_values: jax.Array,
    done: jax.Array,
    truncated: jax.Array,
    gamma: float | jax.Array,
    lam: float | jax.Array,
    bootstrap_truncation: bool | jax.Array = True,
) -> tuple[jax.Array, jax.Array]:
    """GAE(gamma, lambda) advantages and the matching value targets.

    Args:
      rewards, values: float[T, ...], r_t and V(s_t) along time (leading axis).
      next_values: float[T, ...], V of the state each step really reached (the auto-reset
        wrapper's ``final_obs``), so episode ends and the rollout's cut bootstrap correctly.
      done, truncated: bool[T, ...], termination and time-limit truncation of step t.
      bootstrap_truncation: if True (our default) a truncated, non-terminated step bootstraps
        from ``next_values``; if False truncation is treated as terminal (the reference's
        behaviour).

    Returns:
      ``(advantages, targets)``, float[T, ...]: A_t = sum_k (gamma lam)^k delta_{t+k} within
      the episode, with delta_t = r_t + gamma (1 - terminal_t) V(s'_t) - V(s_t); targets are
      A_t + V(s_t) (with lam = 1: bootstrapped discounted returns).
    """
    finished = done | truncated
    terminal = jnp.where(bootstrap_truncation, done, finished)
    deltas = rewards + gamma * jnp.where(terminal, 0.0, next_values) - values
    continues = 1.0 - finished.astype(rewards.dtype)

    def backward(next_advantage, inputs):
        delta, cont = inputs
        advantage = delta + gamma * lam * cont * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(
        backward, jnp.zeros_like(deltas[0]), (deltas, continues), reverse=True
    )
    return advantages, advantages + values
