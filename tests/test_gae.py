"""GAE against a plain NumPy loop with terminations and truncations mixed in; the
log-depth (associative) form against the sequential one."""

import numpy as np
import pytest

from pngail_jax.rl.gae import generalized_advantages

FORMS = ("sequential", "associative")


def numpy_gae(rewards, values, next_values, done, truncated, gamma, lam, bootstrap_truncation):
    """Backward recursion written out per environment and step."""
    num_steps, num_envs = rewards.shape
    advantages = np.zeros_like(rewards)
    for env in range(num_envs):
        running = 0.0
        for t in reversed(range(num_steps)):
            terminal = done[t, env] or (truncated[t, env] and not bootstrap_truncation)
            bootstrap = 0.0 if terminal else next_values[t, env]
            delta = rewards[t, env] + gamma * bootstrap - values[t, env]
            if done[t, env] or truncated[t, env]:
                running = 0.0  # the next step belongs to another episode
            running = delta + gamma * lam * running
            advantages[t, env] = running
    return advantages


@pytest.mark.parametrize("form", FORMS)
@pytest.mark.parametrize("bootstrap_truncation", [True, False])
@pytest.mark.parametrize("lam", [0.97, 1.0])
def test_matches_numpy(bootstrap_truncation, lam, form):
    rng = np.random.default_rng(0)
    shape = (40, 5)
    rewards = rng.normal(size=shape).astype(np.float32)
    values = rng.normal(size=shape).astype(np.float32)
    next_values = rng.normal(size=shape).astype(np.float32)
    done = rng.random(shape) < 0.08
    truncated = rng.random(shape) < 0.08  # some steps are both, as gymnasium allows
    assert (done & truncated).any() and (done & ~truncated).any() and (truncated & ~done).any()
    advantages, targets = generalized_advantages(
        rewards, values, next_values, done, truncated, 0.995, lam, bootstrap_truncation, form
    )
    expected = numpy_gae(
        rewards, values, next_values, done, truncated, 0.995, lam, bootstrap_truncation
    )
    np.testing.assert_allclose(advantages, expected, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(targets, expected + values, rtol=1e-5, atol=1e-5)


def test_hand_worked_example():
    # One env, three steps, gamma 0.5, lambda 1: r = (1, 2, 3), V = 0 everywhere, the
    # episode truncates at step 1 with V(final) = 10 and the rollout ends at step 2 with
    # V(final) = 4.
    #   step 2: delta = 3 + 0.5 * 4 = 5                        -> A = 5
    #   step 1: delta = 2 + 0.5 * 10 = 7 (bootstrapped), cut   -> A = 7
    #   step 0: delta = 1 + 0.5 * V(s_1) = 1, + 0.5 * 7        -> A = 4.5
    # Treating truncation as terminal instead gives A_1 = 2 and A_0 = 1 + 0.5 * 2 = 2.
    zeros = np.zeros((3, 1), np.float32)
    rewards = np.array([[1.0], [2.0], [3.0]], np.float32)
    next_values = np.array([[0.0], [10.0], [4.0]], np.float32)
    done = np.zeros((3, 1), bool)
    truncated = np.array([[False], [True], [False]])
    bootstrapped, _ = generalized_advantages(
        rewards, zeros, next_values, done, truncated, 0.5, 1.0, True
    )
    np.testing.assert_allclose(bootstrapped[:, 0], [4.5, 7.0, 5.0])
    terminal, _ = generalized_advantages(
        rewards, zeros, next_values, done, truncated, 0.5, 1.0, False
    )
    np.testing.assert_allclose(terminal[:, 0], [2.0, 2.0, 5.0])


def random_rollout(num_steps, num_envs, dtype, seed=0):
    """Rewards, values and flags of a rollout with terminations and truncations (some both)."""
    rng = np.random.default_rng(seed)
    shape = (num_steps, num_envs)
    floats = [rng.normal(size=shape).astype(dtype) for _ in range(3)]
    done = rng.random(shape) < 0.02
    truncated = rng.random(shape) < 0.01
    return (*floats, done, truncated)


def associative_vs_sequential(num_steps, num_envs, dtype):
    """Max |associative - sequential| and max |advantage| for both flag treatments and lam
    in {0.97, 1} (the two the trainer uses), on one random rollout."""
    rollout = random_rollout(num_steps, num_envs, dtype)
    worst = []
    for bootstrap in (True, False):
        for lam in (0.97, 1.0):
            args = (*rollout, 0.995, lam, bootstrap)
            sequential, _ = generalized_advantages(*args, form="sequential")
            associative, _ = generalized_advantages(*args, form="associative")
            sequential, associative = np.asarray(sequential), np.asarray(associative)
            assert sequential.dtype == dtype and associative.dtype == dtype
            worst.append(
                [float(np.abs(associative - sequential).max()), float(np.abs(sequential).max())]
            )
    return worst


@pytest.mark.parametrize("shape", [(20, 250), (200, 25), (1000, 4)])
def test_associative_equals_sequential_in_float32(shape):
    # Float32 rounding differs between the two orders of summation; bound it relative to the
    # largest advantage (gamma lam < 1 keeps the sums bounded, so the error does not grow
    # with T beyond a few ulps of the largest term).
    for difference, scale in associative_vs_sequential(*shape, np.float32):
        assert difference <= 1e-5 * scale, (difference, scale)


def x64_associative_vs_sequential():
    return {"worst": associative_vs_sequential(1000, 8, np.float64)}


def test_associative_equals_sequential_under_x64():
    from conftest import run_x64

    for difference, scale in run_x64(__file__, "x64_associative_vs_sequential")["worst"]:
        assert difference <= 1e-12 * scale, (difference, scale)


@pytest.mark.parametrize("form", FORMS)
def test_vector_lambda_gives_each_lambdas_advantages(form):
    rollout = random_rollout(30, 3, np.float32, seed=1)
    both, targets = generalized_advantages(*rollout, 0.99, np.array([0.9, 1.0]), True, form)
    assert both.shape == (2, 30, 3) and targets.shape == (2, 30, 3)
    for index, lam in enumerate((0.9, 1.0)):
        alone, alone_targets = generalized_advantages(*rollout, 0.99, lam, True, form)
        np.testing.assert_allclose(both[index], alone, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(targets[index], alone_targets, rtol=1e-6, atol=1e-6)


def test_unknown_form_is_named():
    with pytest.raises(ValueError, match="GAE form"):
        generalized_advantages(*random_rollout(3, 1, np.float32), 0.99, 0.9, True, "parallel")
