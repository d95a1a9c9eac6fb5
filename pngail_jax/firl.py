"""f-IRL (Ni et al., 2021): a state reward trained by the gradient of an f-divergence between
the demonstrations' and the agent's state marginals.

With h_f(u) = f(u) - u f'(u) and u = rho_E(s) / rho_theta(s), the gradient of
D_f(rho_E || rho_theta) with respect to the reward parameters is (their Theorem 4.1, up to the
temperature and horizon that scale it)

    grad = Cov_{tau ~ agent} ( sum_t h_f(u(s_t)),  sum_t grad r_theta(s_t) ),

and u is estimated by a state discriminator trained to tell demonstration states (label 1)
from agent states: log u = its logit. The three divergences, with the constants that a
covariance ignores dropped (l = log u):

| divergence | f(u) | h_f(u) | h as used |
|---|---|---|---|
| forward KL, KL(rho_E || rho) | u log u | -u | -exp(l) |
| reverse KL, KL(rho || rho_E) | -log u | 1 - log u | -l |
| Jensen-Shannon | u log u - (1 + u) log((1 + u) / 2) | -log((1 + u) / 2) | -softplus(l) |

A divergence is data (three coefficients), so FKL, RKL and JS cells share one program.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp


def divergence_h(log_ratio: jax.Array, fkl_coef, rkl_coef, js_coef) -> jax.Array:
    """h_f at u = exp(log_ratio) for the divergence mixing FKL, RKL and JS by the coefs."""
    fkl = jnp.where(fkl_coef != 0, -jnp.exp(jnp.minimum(log_ratio, 30.0)), 0.0)
    return fkl_coef * fkl + rkl_coef * (-log_ratio) + js_coef * (-jax.nn.softplus(log_ratio))


def covariance_surrogate(h_sums: jax.Array, reward_sums: jax.Array):
    """A loss whose gradient is f-IRL's estimator: mean_tau (H_tau - mean H) R_theta(tau).

    h_sums float[M]: sum_t h_f over each of M agent trajectories (no gradient flows through
    it); reward_sums float[M]: sum_t r_theta(s_t), a function of the reward parameters. Its
    gradient is the sample covariance (1 / M) sum_tau (H_tau - mean H) grad R_theta(tau).
    """
    chex.assert_equal_shape([h_sums, reward_sums])
    centred = jax.lax.stop_gradient(h_sums - h_sums.mean())
    loss = jnp.mean(centred * reward_sums)
    return loss, {"firl/loss": loss, "firl/h_std": jnp.std(h_sums)}


def state_discriminator_loss(logits_demo: jax.Array, logits_agent: jax.Array):
    """Logistic loss of the state discriminator, demonstration states label 1: its logit
    estimates log rho_E(s) / rho_agent(s) when the two batches are the same size."""
    loss = jnp.mean(jax.nn.softplus(-logits_demo)) + jnp.mean(jax.nn.softplus(logits_agent))
    return loss, {"firl/disc_loss": loss}
