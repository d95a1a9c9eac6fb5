"""Behaviour cloning: the policy's Gaussian log-likelihood of the demonstrations' actions,
optionally weighted per row by its confidence (confidence-weighted BC)."""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp

from pngail_jax.fitting import fit_with_adam
from pngail_jax.networks import gaussian_log_prob


@dataclasses.dataclass(frozen=True)
class BCConfig:
    num_steps: int = 2_000
    batch_size: int = 128
    learning_rate: float = 1e-3

    def __post_init__(self):
        for name in ("num_steps", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"BCConfig.{name} must be a positive integer, got {value!r}")


def bc_loss(mean: jax.Array, log_std: jax.Array, actions: jax.Array, weights: jax.Array):
    """-sum_i w_i log pi(a_i | s_i) / sum_i w_i, with the policy's mean float[B, A] and
    log_std float[A] on a batch of actions float[B, A] and weights float[B]."""
    chex.assert_equal_shape([mean, actions])
    log_prob = gaussian_log_prob(mean, log_std, actions)
    loss = -jnp.sum(weights * log_prob) / jnp.maximum(weights.sum(), 1e-8)
    return loss, {"bc/loss": loss}


def train_bc(config: BCConfig, policy_apply, params, observations, actions, weights, key):
    """Adam on ``bc_loss`` from ``params`` with batches drawn with probability proportional
    to ``weights`` float[N] (so weights 0 are never drawn; all equal: plain BC). Returns
    ``(params, metrics)``, metrics float[num_steps]."""
    probabilities = weights / jnp.maximum(weights.sum(), 1e-8)

    def loss_fn(params, key):
        rows = jax.random.choice(key, observations.shape[0], (config.batch_size,), p=probabilities)
        mean, log_std = policy_apply(params, observations[rows])
        return bc_loss(mean, log_std, actions[rows], jnp.ones(rows.shape))

    keys = jax.random.split(key, config.num_steps)
    return fit_with_adam(loss_fn, params, config.learning_rate, keys)
