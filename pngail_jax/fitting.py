"""Supervised fitting as one scan: Adam steps of a loss that draws its own batch from a key."""

from __future__ import annotations

import jax
import jax.numpy as jnp
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


def adam_step(params, optimizer_state, grads, learning_rate):
    """One Adam step with its learning rate as a value (a grid's cells may differ):
    ``optax.scale_by_adam()``'s update of ``optimizer_state`` (its ``init``), then
    ``-learning_rate`` times it. Returns ``(params, optimizer_state)``."""
    updates, optimizer_state = optax.scale_by_adam().update(grads, optimizer_state)
    step = jax.tree.map(lambda u: -learning_rate * u, updates)
    return optax.apply_updates(params, step), optimizer_state


def squared_norm(params) -> jax.Array:
    """||theta||^2: the sum of squares of every leaf of ``params`` (weights and biases), the
    L2 term the CAIL codebase adds to its losses (``parameters_to_vector(p).norm() ** 2``).
    float[]."""
    return sum(jnp.sum(jnp.square(leaf)) for leaf in jax.tree.leaves(params))


def gradients_agree(grads, other_grads) -> jax.Array:
    """bool[]: the dot product of two gradients (pytrees of one structure) is >= 0."""
    return sum(jax.tree.leaves(jax.tree.map(jnp.vdot, grads, other_grads))) >= 0


def tree_where(condition, on_true, on_false):
    """``jnp.where`` over two pytrees of one structure."""
    return jax.tree.map(lambda a, b: jnp.where(condition, a, b), on_true, on_false)
