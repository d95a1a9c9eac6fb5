"""CAIL's pieces against NumPy: the renormalisation, the confidence-weighted loss, the margin
ranking loss over all pairs (with the codebase's smoothing) and its gradient, and the
lookahead's second-order gradient on beta."""

import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.adversarial import cail


def np_softplus(x):
    return np.logaddexp(0, x)


def test_renormalize_divides_by_the_mean_then_clips():
    beta = np.array([0.2, 1.0, 3.0, 5.8])  # mean 2.5
    expected = np.clip(beta / 2.5, 0, 2)
    np.testing.assert_allclose(cail.renormalize(jnp.asarray(beta), 2.0), expected, rtol=1e-6)
    np.testing.assert_array_equal(cail.renormalize(jnp.ones(7), 2.0), 1.0)  # exactly 1


def test_inner_loss_matches_numpy():
    rng = np.random.default_rng(0)
    z_agent, z_demo, beta = rng.normal(size=30), rng.normal(size=20), rng.uniform(0, 2, 20)
    expected = np.mean(np_softplus(-z_agent)) + np.mean(beta * np_softplus(z_demo))
    with jax.enable_x64(True):
        got = cail.inner_loss(*map(jnp.asarray, (z_agent, z_demo, beta)))
    np.testing.assert_allclose(got, expected, rtol=1e-12)


def numpy_margin_loss(returns, truth, smoothing=cail.SMOOTHING):
    loss = 0.0
    for i, j in itertools.combinations(range(len(returns)), 2):
        if truth[i] == truth[j]:
            continue
        y = 1.0 if truth[i] > truth[j] else -1.0
        difference = returns[i] - returns[j]
        if abs(difference) < smoothing:
            loss += (abs(difference) - smoothing) ** 2 / (4 * smoothing)
        else:
            loss += max(0.0, -y * difference)
    return loss


def test_margin_ranking_loss_sums_every_pair_and_matches_numpy_with_its_gradient():
    rng = np.random.default_rng(1)
    returns = rng.normal(size=8)
    returns[5] = returns[2] + 3e-6  # inside the smoothing band
    truth = rng.uniform(size=8)
    truth[7] = truth[3]  # a tie: no information
    with jax.enable_x64(True):
        loss, metrics = cail.margin_ranking_loss(jnp.asarray(returns), jnp.asarray(truth))
        grad = jax.grad(lambda r: cail.margin_ranking_loss(r, jnp.asarray(truth))[0])(
            jnp.asarray(returns)
        )
    np.testing.assert_allclose(loss, numpy_margin_loss(returns, truth), rtol=1e-10)
    step = 1e-7  # central differences away from the kinks
    for index in (0, 4):
        bump = np.eye(8)[index] * step
        expected = (
            numpy_margin_loss(returns + bump, truth) - numpy_margin_loss(returns - bump, truth)
        ) / (2 * step)
        np.testing.assert_allclose(grad[index], expected, rtol=1e-5, atol=1e-7)
    pairs = [(i, j) for i, j in itertools.combinations(range(8), 2) if truth[i] != truth[j]]
    correct = sum((returns[i] - returns[j]) * (truth[i] - truth[j]) > 0 for i, j in pairs)
    np.testing.assert_allclose(metrics["cail/ranking_accuracy"], correct / len(pairs))


def test_trajectory_returns_sum_the_valid_steps():
    features = jnp.arange(2 * 3 * 1, dtype=jnp.float32).reshape(2, 3, 1)
    valid = jnp.array([[True, True, False], [True, True, True]])
    got = cail.trajectory_returns(lambda x: 2 * x[..., 0], features, valid)
    np.testing.assert_allclose(got, [2 * (0 + 1), 2 * (3 + 4 + 5)])


def test_the_lookahead_gradient_raises_beta_on_the_better_trajectory():
    """A linear 'discriminator' z(x) = w x on 1-d inputs: demonstration rows at x = +1 (the
    better trajectory's) and x = -1 (the worse one's). L = mean sp(-w x_agent) + mean beta
    sp(w x_demo); w' = w - lr dL/dw; R(tau) = sum sp(-w' x) over tau's steps. The outer
    gradient on beta, by hand through the lookahead, equals jax's, and it raises the better
    trajectory's beta (negative gradient) and lowers the worse one's."""
    lr, w = 0.5, 0.3
    x_agent, x_demo = np.array([0.2, -0.4]), np.array([1.0, -1.0])
    better, worse = np.array([1.0, 1.0]), np.array([-1.0, -1.0])  # trajectories' steps

    def outer(beta):
        def inner(weight):
            return jnp.mean(jax.nn.softplus(-weight * x_agent)) + jnp.mean(
                beta * jax.nn.softplus(weight * x_demo)
            )

        lookahead = w - lr * jax.grad(inner)(w)
        returns = jnp.stack([jax.nn.softplus(-lookahead * t).sum() for t in (better, worse)])
        # worse's return above better's here: the hinge is active
        return cail.margin_ranking_loss(returns, jnp.array([1.0, 0.0]))[0]

    with jax.enable_x64(True):
        grad = np.asarray(jax.grad(outer)(jnp.ones(2)))
    sigmoid = lambda v: 1 / (1 + np.exp(-v))  # noqa: E731
    # dw'/dbeta_k = -lr * d/dbeta_k [beta_k sigma(w x_k) x_k / 2] = -lr sigma(w x_k) x_k / 2
    dw_dbeta = -lr * sigmoid(w * x_demo) * x_demo / 2
    # lookahead w' and d(R_worse - R_better)/dw' (the hinge max(0, R_worse - R_better))
    w_new = w - lr * (
        np.mean(-sigmoid(-w * x_agent) * x_agent) + np.mean(sigmoid(w * x_demo) * x_demo)
    )
    d_return = lambda t: np.sum(-sigmoid(-w_new * t) * t)  # noqa: E731
    assert np.sum(np_softplus(-w_new * worse)) > np.sum(np_softplus(-w_new * better))
    expected = (d_return(worse) - d_return(better)) * dw_dbeta
    np.testing.assert_allclose(grad, expected, rtol=1e-9)
    assert grad[0] < 0 < grad[1]


@pytest.mark.parametrize(
    "field, value", [("num_rounds", 0), ("num_trajectories", 1), ("pretrain_iterations", -1)]
)
def test_config_refuses_bad_values(field, value):
    with pytest.raises(ValueError, match=f"CAILConfig.{field}"):
        cail.CAILConfig(**{field: value})
