"""The natural-gradient step of TRPO: Fisher-vector products, conjugate gradient, line search.

Every loop has a fixed iteration count and uses masks instead of early exits, so all cells of
a vmapped grid do the same work (docs/architecture.md).
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp


def conjugate_gradient(
    matrix_vector_product: Callable[[jax.Array], jax.Array],
    b: jax.Array,
    num_iterations: int,
    residual_tolerance: float = 1e-10,
) -> jax.Array:
    """Approximately solves A x = b for symmetric positive-definite A, from x = 0.

    Runs exactly ``num_iterations`` products; once the squared residual is below
    ``residual_tolerance`` the remaining iterations leave x unchanged (the reference breaks
    out of its loop there).
    """

    def body(carry, _):
        x, r, p, r_dot_r = carry
        active = r_dot_r >= residual_tolerance
        a_p = matrix_vector_product(p)
        alpha = jnp.where(active, r_dot_r / jnp.maximum(jnp.vdot(p, a_p), 1e-30), 0.0)
        x = x + alpha * p
        r = r - alpha * a_p
        new_r_dot_r = jnp.vdot(r, r)
        beta = jnp.where(active, new_r_dot_r / jnp.maximum(r_dot_r, 1e-30), 0.0)
        p = jnp.where(active, r + beta * p, p)
        return (x, r, p, jnp.where(active, new_r_dot_r, r_dot_r)), None

    initial = (jnp.zeros_like(b), b, b, jnp.vdot(b, b))
    (x, _, _, _), _ = jax.lax.scan(body, initial, None, length=num_iterations)
    return x


def backtracking_line_search(
    loss: Callable[[jax.Array], jax.Array],
    x: jax.Array,
    full_step: jax.Array,
    expected_improvement: jax.Array,
    num_backtracks: int = 10,
    accept_ratio: float = 0.1,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The reference's line search over fractions 0.5^k, k = 0..num_backtracks-1.

    Takes the first fraction whose actual improvement is positive and more than
    ``accept_ratio`` times the expected (linear) improvement; keeps ``x`` if none is.
    All fractions are evaluated (fixed work).

    Returns ``(new_x, accepted, fraction)``: fraction is 0 when no step was accepted.
    """
    base_loss = loss(x)
    fractions = 0.5 ** jnp.arange(num_backtracks, dtype=x.dtype)
    new_losses = jax.vmap(lambda f: loss(x + f * full_step))(fractions)
    actual = base_loss - new_losses
    ratio = actual / (expected_improvement * fractions)
    acceptable = (ratio > accept_ratio) & (actual > 0)
    accepted = jnp.any(acceptable)
    fraction = jnp.where(accepted, fractions[jnp.argmax(acceptable)], 0.0)
    return x + fraction * full_step, accepted, fraction


def natural_gradient_step(
    surrogate_loss: Callable[[jax.Array], jax.Array],
    mean_kl: Callable[[jax.Array], jax.Array],
    flat_params: jax.Array,
    max_kl: float | jax.Array,
    damping: float | jax.Array,
    num_cg_iterations: int,
    num_backtracks: int,
    fisher_vector_product: Callable[[jax.Array], jax.Array] | None = None,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """One TRPO update of flat parameters, as the reference's ``trpo_step``.

    Args:
      surrogate_loss: params -> float[], the loss to minimise (-advantage-weighted ratio).
      mean_kl: params -> float[], mean KL(pi_old || pi_params), 0 at ``flat_params``.
      fisher_vector_product: v -> (F + damping I) v; by default the Hessian of ``mean_kl``
        times v (the reference's form) plus damping.

    Returns ``(new_flat_params, metrics)`` with ``trpo/accepted`` (0/1), ``trpo/step_fraction``,
    ``trpo/expected_improvement``.
    """
    loss_grad = jax.grad(surrogate_loss)(flat_params)
    if fisher_vector_product is None:
        fisher_vector_product = hessian_vector_product(mean_kl, flat_params, damping)
    step_direction = conjugate_gradient(fisher_vector_product, -loss_grad, num_cg_iterations)
    shs = 0.5 * jnp.vdot(step_direction, fisher_vector_product(step_direction))
    lagrange_multiplier = jnp.sqrt(jnp.maximum(shs, 1e-30) / max_kl)
    full_step = step_direction / lagrange_multiplier
    expected_improvement = jnp.vdot(-loss_grad, step_direction) / lagrange_multiplier
    new_params, accepted, fraction = backtracking_line_search(
        surrogate_loss, flat_params, full_step, expected_improvement, num_backtracks
    )
    metrics = {
        "trpo/accepted": accepted.astype(flat_params.dtype),
        "trpo/step_fraction": fraction,
        "trpo/expected_improvement": expected_improvement,
    }
    return new_params, metrics


def hessian_vector_product(
    function: Callable[[jax.Array], jax.Array], at: jax.Array, damping: float | jax.Array
) -> Callable[[jax.Array], jax.Array]:
    """v -> (Hessian of ``function`` at ``at``) v + damping v, by forward-over-reverse."""
    gradient = jax.grad(function)

    def product(v):
        return jax.jvp(gradient, (at,), (v,))[1] + damping * v

    return product
