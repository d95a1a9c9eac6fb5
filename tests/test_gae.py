"""GAE against a plain NumPy loop with terminations and truncations mixed in."""

import numpy as np
import pytest

from pngail_jax.rl.gae import generalized_advantages


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


@pytest.mark.parametrize("bootstrap_truncation", [True, False])
@pytest.mark.parametrize("lam", [0.97, 1.0])
def test_matches_numpy(bootstrap_truncation, lam):
    rng = np.random.default_rng(0)
    shape = (40, 5)
    rewards = rng.normal(size=shape).astype(np.float32)
    values = rng.normal(size=shape).astype(np.float32)
    next_values = rng.normal(size=shape).astype(np.float32)
    done = rng.random(shape) < 0.08
    truncated = rng.random(shape) < 0.08  # some steps are both, as gymnasium allows
    assert (done & truncated).any() and (done & ~truncated).any() and (truncated & ~done).any()
    advantages, targets = generalized_advantages(
        rewards, values, next_values, done, truncated, 0.995, lam, bootstrap_truncation
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
