"""Conjugate gradient, Fisher-vector products and the natural-gradient step."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.flatten_util import ravel_pytree

from pngail_jax.networks import GaussianPolicy, gaussian_entropy, gaussian_kl, gaussian_log_prob
from pngail_jax.rl.trpo import (
    backtracking_line_search,
    conjugate_gradient,
    gauss_newton_fisher_product,
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


def _numpy_line_search(loss, x, full_step, expected, num_backtracks=10, accept_ratio=0.1):
    """The reference's loop, written out: the first fraction 0.5^k whose improvement is
    positive and above accept_ratio x expected x fraction; none: x unchanged."""
    base = loss(x)
    for k in range(num_backtracks):
        fraction = 0.5**k
        actual = base - loss(x + fraction * full_step)
        if actual > 0 and actual / (expected * fraction) > accept_ratio:
            return x + fraction * full_step, True, fraction
    return x, False, 0.0


def test_line_search_stops_where_the_reference_loop_does_also_under_vmap():
    """On a quadratic bowl, steps that overshoot by different factors are taken at
    different fractions (0.5^0 ... none); each cell of a vmapped search equals the NumPy
    loop, though the batched loop runs until the last cell has taken one."""
    with jax.enable_x64(True):
        x = jnp.array([1.0, -2.0])
        loss = lambda p: jnp.sum(p**2)  # noqa: E731
        overshoots = jnp.array([1.0, 3.0, 9.0, 40.0, 5000.0, -1.0])  # -1: uphill
        steps = -overshoots[:, None] * x  # x + f * step = x (1 - f * overshoot)
        expected = jnp.full(len(overshoots), 5.0)
        new_x, accepted, fraction = jax.jit(
            jax.vmap(lambda step, e: backtracking_line_search(loss, x, step, e))
        )(steps, expected)
        numpy_loss = lambda p: float(np.sum(p**2))  # noqa: E731
        taken = set()
        for i, step in enumerate(np.asarray(steps)):
            want_x, want_accepted, want_fraction = _numpy_line_search(
                numpy_loss, np.asarray(x), step, 5.0
            )
            assert bool(accepted[i]) == want_accepted and float(fraction[i]) == want_fraction
            np.testing.assert_allclose(new_x[i], want_x, rtol=0, atol=1e-15)
            taken.add(want_fraction)
    assert 0.0 in taken and len(taken) >= 4, taken  # cells stop at different fractions


def test_fisher_subsample_keeps_every_environment():
    from pngail_jax.rl.on_policy import RolloutConfig
    from pngail_jax.rl.trpo import fisher_sample_indices

    config = RolloutConfig(num_envs=4, unroll_length=6)
    # Flattened time-major batch: row t * 4 + n. Every 3rd step (t = 0, 3) of all 4 envs.
    np.testing.assert_array_equal(fisher_sample_indices(config, 3), [0, 1, 2, 3, 12, 13, 14, 15])
    np.testing.assert_array_equal(fisher_sample_indices(config, 1), np.arange(24))


def _numpy_gaussian(rng, shape):
    return rng.normal(size=shape), rng.normal(scale=0.5, size=shape)


def test_gaussian_log_prob_kl_and_entropy_against_numpy():
    """The diagonal Gaussian's formulas, written out independently in float64:
    log N(a; m, s^2) = sum -(a - m)^2 / 2s^2 - log s - log(2 pi) / 2;
    KL(N0 || N1) = sum log(s1 / s0) + (s0^2 + (m0 - m1)^2) / 2 s1^2 - 1/2;
    H = sum log s + log(2 pi e) / 2."""
    rng = np.random.default_rng(3)
    (mean_0, log_std_0), (mean_1, log_std_1) = (_numpy_gaussian(rng, (7, 3)) for _ in range(2))
    action = rng.normal(size=(7, 3))
    s0, s1 = np.exp(log_std_0), np.exp(log_std_1)
    log_prob = np.sum(
        -((action - mean_0) ** 2) / (2 * s0**2) - np.log(s0) - 0.5 * np.log(2 * np.pi), axis=-1
    )
    kl = np.sum(np.log(s1 / s0) + (s0**2 + (mean_0 - mean_1) ** 2) / (2 * s1**2) - 0.5, axis=-1)
    entropy = np.sum(np.log(s0[0]) + 0.5 * np.log(2 * np.pi * np.e))
    f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
    np.testing.assert_allclose(
        gaussian_log_prob(f32(mean_0), f32(log_std_0), f32(action)), log_prob, rtol=1e-5
    )
    np.testing.assert_allclose(
        gaussian_kl(f32(mean_0), f32(log_std_0), f32(mean_1), f32(log_std_1)), kl, rtol=1e-5
    )
    np.testing.assert_allclose(gaussian_entropy(f32(log_std_0[0])), entropy, rtol=1e-5)
    # KL of a distribution with itself is 0, and KL is never negative
    np.testing.assert_allclose(
        gaussian_kl(f32(mean_0), f32(log_std_0), f32(mean_0), f32(log_std_0)), 0.0, atol=1e-6
    )
    assert (kl >= 0).all()


def test_the_surrogate_loss_and_its_gradient_against_numpy():
    """TRPO's surrogate -mean(A exp(log pi(a|s) - log pi_old(a|s))) at a policy's parameters,
    against the same formula from the policy's outputs in NumPy; at the old parameters the
    ratio is 1, so the loss is -mean(A) and its gradient is -mean(A grad log pi)."""
    from pngail_jax import envs
    from pngail_jax.rl.on_policy import RolloutConfig
    from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams

    trpo = TRPO(
        RolloutConfig(num_envs=2, unroll_length=4, hidden_sizes=(5,)),
        envs.make("Pendulum-v1"),
        TRPOConfig(num_value_minibatches=2),
    )
    params = trpo.policy.init(jax.random.key(1), jnp.zeros(3))
    rng = np.random.default_rng(4)
    obs = jnp.asarray(rng.normal(size=(8, 3)), jnp.float32)
    actions = jnp.asarray(rng.normal(size=(8, 1)), jnp.float32)
    advantages = jnp.asarray(rng.normal(size=8), jnp.float32)
    mean, log_std = trpo.policy.apply(params, obs)
    old_log_prob = gaussian_log_prob(mean, log_std, actions) + jnp.asarray(
        rng.normal(scale=0.1, size=8), jnp.float32
    )  # an older policy than these parameters
    objective = trpo.policy_objective(
        TRPOHyperparams.create(), params, obs, actions, old_log_prob, advantages
    )
    ratio = np.exp(np.asarray(gaussian_log_prob(mean, log_std, actions) - old_log_prob))
    np.testing.assert_allclose(
        objective.surrogate_loss(objective.flat_params),
        -np.mean(np.asarray(advantages) * ratio),
        rtol=1e-5,
    )
    # with the old log-probabilities those of these parameters: ratio 1, gradient of -mean(A log pi)
    current = gaussian_log_prob(mean, log_std, actions)
    objective = trpo.policy_objective(
        TRPOHyperparams.create(), params, obs, actions, current, advantages
    )
    np.testing.assert_allclose(
        objective.surrogate_loss(objective.flat_params), -np.mean(advantages), rtol=1e-5
    )

    def log_prob_loss(flat):
        mean, log_std = trpo.policy.apply(objective.unravel(flat), obs)
        return -jnp.mean(advantages * gaussian_log_prob(mean, log_std, actions))

    np.testing.assert_allclose(
        jax.grad(objective.surrogate_loss)(objective.flat_params),
        jax.grad(log_prob_loss)(objective.flat_params),
        rtol=1e-4,
        atol=1e-6,
    )


def test_value_epochs_are_one_epoch_fits_in_a_row_with_folded_keys():
    """``num_value_epochs=3`` fits the value as three one-epoch fits one after another, the
    e-th on ``fold_in(key, e)``'s permutation (the first on ``key``'s, so one epoch is the
    reference's fit unchanged); the loss on the batch falls with more epochs."""
    from pngail_jax import envs
    from pngail_jax.rl.on_policy import RolloutConfig
    from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams

    rollout = RolloutConfig(num_envs=2, unroll_length=12, hidden_sizes=(8,))
    pendulum = envs.make("Pendulum-v1")

    def learner(epochs):
        return TRPO(rollout, pendulum, TRPOConfig(num_value_minibatches=4, num_value_epochs=epochs))

    one, three = learner(1), learner(3)
    state = one.init(jax.random.key(0))
    rng = np.random.default_rng(5)
    obs = jnp.asarray(rng.normal(size=(24, 3)), jnp.float32)
    targets = jnp.asarray(rng.normal(size=24) + obs[:, 0], jnp.float32)
    hyperparams, key = TRPOHyperparams.create(), jax.random.key(7)
    params, opt_state, _ = three.fit_value(hyperparams, state, obs, targets, key)
    chained = state
    for epoch_key in (key, jax.random.fold_in(key, 1), jax.random.fold_in(key, 2)):
        value_params, value_opt, _ = one.fit_value(hyperparams, chained, obs, targets, epoch_key)
        chained = chained.replace(value_params=value_params, value_optimizer_state=value_opt)
    for got, want in zip(jax.tree.leaves((params, opt_state)),
                         jax.tree.leaves((chained.value_params, chained.value_optimizer_state)),
                         strict=True):  # fmt: skip
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)

    def loss(value_params):
        return float(jnp.mean((one.value.apply(value_params, obs) - targets) ** 2))

    after_one = one.fit_value(hyperparams, state, obs, targets, key)[0]
    assert loss(params) < loss(after_one) < loss(state.value_params)
    with pytest.raises(ValueError, match="num_value_epochs"):
        TRPOConfig(num_value_epochs=0)
