"""Supervised fitting as one scan: Adam steps of a loss that draws its own batch from a key."""

from __future__ import annotations

import jax
import optax


def fit_with_adam(loss_fn, params, learning_rate: float, keys: jax.Array):
    """One Adam step of ``loss_fn(params, key) -> (loss, metrics)`` per key of ``keys``
    (key[S]). Returns ``(params, metrics)``, each metric float[S]. Pure and jittable."""
    optimizer = optax.adam(learning_rate)

    def step(carry, key):
        params, optimizer_state = carry
        grads, metrics = jax.grad(loss_fn, has_aux=True)(params, key)
        updates, optimizer_state = optimizer.update(grads, optimizer_state, params)
        return (optax.apply_updates(params, updates), optimizer_state), metrics

    (params, _), metrics = jax.lax.scan(step, (params, optimizer.init(params)), keys)
    return params, metrics
