"""Conjugate gradient, Fisher-vector products and the natural-gradient step."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

from pngail_jax.networks import GaussianPolicy, gaussian_kl, gaussian_log_prob
from pngail_jax.rl.train import gauss_newton_fisher_product
from pngail_jax.rl.trpo import (
    backtracking_line_search,
    conjugate_gradient,
    hessian_vector_product,
    natural_gradient_step,
)


@pytest.mark.parametrize("size", [5, 20])
def test_conjugate_gradient_solves_spd_systems(size):
    rng = np.random.default_rng(size)
    a = rng.normal(size=(size, size))
    matrix = a @ a.T + 0.5 * np.eye(size)
    b = rng.normal(size=size)
    with jax.enable_x64(True):
        x = conjugate_gradient(lambda v: jnp.asarray(matrix) @ v, jnp.asarray(b), 3 * size)
    np.testing.assert_allclose(x, np.linalg.solve(matrix, b), rtol=1e-6, atol=1e-8)


def test_conjugate_gradient_stops_changing_after_convergence():
    matrix = jnp.diag(jnp.array([1.0, 2.0, 4.0]))
    b = jnp.array([1.0, 1.0, 1.0])
    exact = conjugate_gradient(lambda v: matrix @ v, b, 3)
    many = conjugate_gradient(lambda v: matrix @ v, b, 50)
    np.testing.assert_allclose(many, [1.0, 0.5, 0.25], rtol=1e-5)
    np.testing.assert_allclose(many, exact, rtol=1e-5)
    assert np.isfinite(many).all()


@pytest.fixture(scope="module")
def tiny_policy():
    """A 3 -> 4 -> 2 Gaussian policy with random (not initial) parameters and a batch."""
    policy = GaussianPolicy(action_size=2, hidden_sizes=(4,))
    key_params, key_obs, key_noise = jax.random.split(jax.random.key(0), 3)
    obs = jax.random.normal(key_obs, (16, 3))
    params = policy.init(key_params, obs[0])
    flat, unravel = ravel_pytree(params)
    flat = flat + 0.3 * jax.random.normal(key_noise, flat.shape)
    return policy, flat, unravel, obs


def _mean_kl_at(policy, unravel, flat0, obs):
    old_mean, old_log_std = policy.apply(unravel(flat0), obs)

    def mean_kl(flat):
        mean, log_std = policy.apply(unravel(flat), obs)
        return jnp.mean(gaussian_kl(old_mean, old_log_std, mean, log_std))

    return mean_kl


@pytest.mark.parametrize("form", ["hessian", "gauss_newton"])
def test_fisher_vector_product_equals_explicit_hessian(tiny_policy, form):
    policy, flat, unravel, obs = tiny_policy
    mean_kl = _mean_kl_at(policy, unravel, flat, obs)
    hessian = jax.hessian(mean_kl)(flat)  # the explicit matrix, by forward-over-reverse
    damping = 0.1
    if form == "hessian":
        product = hessian_vector_product(mean_kl, flat, damping)
    else:
        product = gauss_newton_fisher_product(policy, unravel, flat, obs, damping)
    rng = np.random.default_rng(1)
    for _ in range(3):
        v = jnp.asarray(rng.normal(size=flat.shape), jnp.float32)
        np.testing.assert_allclose(product(v), hessian @ v + damping * v, rtol=2e-4, atol=2e-5)


def test_accepted_step_keeps_kl_near_bound_and_improves_surrogate(tiny_policy):
    policy, flat, unravel, obs = tiny_policy
    key_action, key_adv = jax.random.split(jax.random.key(1))
    mean, log_std = policy.apply(unravel(flat), obs)
    actions = mean + jnp.exp(log_std) * jax.random.normal(key_action, mean.shape)
    old_log_prob = gaussian_log_prob(mean, log_std, actions)
    advantages = jax.random.normal(key_adv, (obs.shape[0],))

    def surrogate(f):
        m, s = policy.apply(unravel(f), obs)
        return -jnp.mean(advantages * jnp.exp(gaussian_log_prob(m, s, actions) - old_log_prob))

    mean_kl = _mean_kl_at(policy, unravel, flat, obs)
    max_kl = 0.01
    new_flat, metrics = natural_gradient_step(surrogate, mean_kl, flat, max_kl, 0.1, 10, 10)
    assert metrics["trpo/accepted"] == 1.0
    assert surrogate(new_flat) < surrogate(flat)
    kl = float(mean_kl(new_flat))
    # The quadratic model puts the full step on the bound; the accepted fraction 0.5^k of it
    # has KL about 0.25^k times that.
    fraction = float(metrics["trpo/step_fraction"])
    assert 0.3 * max_kl * fraction**2 < kl < 2.0 * max_kl * fraction**2, (kl, fraction)


def test_line_search_keeps_parameters_when_nothing_improves():
    x = jnp.array([1.0, -1.0])
    loss = lambda p: jnp.sum(p**2)  # noqa: E731
    step = jnp.array([1.0, -1.0])  # uphill everywhere along the line
    new_x, accepted, fraction = backtracking_line_search(loss, x, step, jnp.array(1.0))
    assert not accepted and fraction == 0.0
    np.testing.assert_array_equal(new_x, x)
    # Downhill: the first fraction whose improvement beats 0.1 x expected is taken.
    new_x, accepted, fraction = backtracking_line_search(loss, x, -step, jnp.array(4.0))
    assert accepted and fraction == 1.0
    np.testing.assert_allclose(new_x, [0.0, 0.0])


def test_fisher_subsample_keeps_every_environment():
    from pngail_jax.rl.train import TRPOConfig, fisher_sample_indices

    config = TRPOConfig(num_envs=4, unroll_length=6, fisher_subsample=3, num_value_minibatches=2)
    # Flattened time-major batch: row t * 4 + n. Every 3rd step (t = 0, 3) of all 4 envs.
    np.testing.assert_array_equal(fisher_sample_indices(config), [0, 1, 2, 3, 12, 13, 14, 15])
    every = fisher_sample_indices(TRPOConfig(num_envs=4, unroll_length=6, num_value_minibatches=2))
    np.testing.assert_array_equal(every, np.arange(24))
