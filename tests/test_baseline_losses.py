"""The appendix baselines' losses against independent NumPy computations of their formulas:
T-REX's Bradley-Terry loss on snippet sums, BC, CAIL's outer loss (f-IRL's: tests/test_firl.py)."""

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax import bc, ranking

RNG = np.random.default_rng(0)


def test_bradley_terry_on_snippet_sums_matches_numpy():
    num_trajectories, steps, length, num_pairs = 5, 12, 4, 9
    step_rewards = RNG.normal(size=(num_trajectories, steps)).astype(np.float32)
    lengths = np.array([12, 3, 7, 12, 5], np.int32)  # padding beyond each length
    trajectories = ranking.Trajectories(
        observations=jnp.zeros((num_trajectories, steps, 1)),
        actions=jnp.zeros((num_trajectories, steps, 1)),
        lengths=jnp.asarray(lengths),
        score=jnp.array([0.1, 0.5, 0.5, 1.0, 0.0]),
    )
    pairs = ranking.sample_pairs(jax.random.key(1), trajectories, num_pairs, length)
    features = jnp.asarray(step_rewards)[..., None]  # a reward that reads its one feature
    loss, metrics = ranking.ranking_loss(lambda x: x[..., 0], features, trajectories, pairs, length)

    def snippet(index, start):  # the formula: sum of r over the snippet's real steps
        stop = min(start + length, lengths[index])
        return step_rewards[index, start:stop].sum()

    worse = np.array([snippet(i, s) for i, s in zip(pairs.worse, pairs.worse_start, strict=True)])
    better = np.array(
        [snippet(i, s) for i, s in zip(pairs.better, pairs.better_start, strict=True)]
    )
    score = np.asarray(trajectories.score)
    weight = (score[pairs.worse] != score[pairs.better]).astype(float)
    assert np.all(score[pairs.better] >= score[pairs.worse])
    # -log(exp(R_better) / (exp(R_better) + exp(R_worse))), averaged over unequal pairs
    expected = np.sum(weight * -np.log(np.exp(better) / (np.exp(better) + np.exp(worse))))
    np.testing.assert_allclose(loss, expected / weight.sum(), rtol=1e-5)
    accuracy = np.sum(weight * (better > worse)) / weight.sum()
    np.testing.assert_allclose(metrics["ranking/accuracy"], accuracy, rtol=1e-6)
    # Snippets start where `length` steps fit, or at 0.
    starts = np.concatenate([pairs.worse_start, pairs.better_start])
    rows = np.concatenate([pairs.worse, pairs.better])
    assert np.all(starts <= np.maximum(lengths[rows] - length, 0))


def test_trex_learns_a_reward_that_ranks_the_trajectories():
    # Trajectory k visits states around k: the better-scored, the larger the state.
    observations = np.stack([np.full((20, 1), k, np.float32) for k in range(4)])
    observations += RNG.normal(scale=0.1, size=observations.shape).astype(np.float32)
    trajectories = ranking.Trajectories(
        observations=jnp.asarray(observations),
        actions=jnp.zeros((4, 20, 1)),
        lengths=jnp.full(4, 20, jnp.int32),
        score=jnp.arange(4.0),
    )
    config = ranking.RankingConfig(num_steps=300, snippet_length=5, hidden_sizes=(16,))
    params, metrics = ranking.train_ranking_reward(config, trajectories, jax.random.key(0))
    returns = ranking.StateReward(config.hidden_sizes)(params, trajectories.observations).sum(1)
    assert np.all(np.diff(np.asarray(returns)) > 0)  # the learned reward orders them
    assert metrics["ranking/loss"][-50:].mean() < metrics["ranking/loss"][:50].mean() / 2


def test_bc_loss_is_the_weighted_gaussian_negative_log_likelihood():
    mean = RNG.normal(size=(8, 2)).astype(np.float32)
    log_std = RNG.normal(size=2).astype(np.float32) * 0.3
    actions = RNG.normal(size=(8, 2)).astype(np.float32)
    weights = RNG.uniform(size=8).astype(np.float32)
    loss, _ = bc.bc_loss(jnp.asarray(mean), jnp.asarray(log_std), jnp.asarray(actions), weights)
    std = np.exp(log_std)
    log_density = -0.5 * ((actions - mean) / std) ** 2 - np.log(std * np.sqrt(2 * np.pi))
    expected = -np.sum(weights * log_density.sum(axis=1)) / weights.sum()
    np.testing.assert_allclose(loss, expected, rtol=1e-5)


def test_cail_outer_loss_and_its_gradient_match_numpy():
    """A linear discriminator z = theta . x: the inner step, the lookahead reward sp(-z) on
    the trajectories and the Bradley-Terry loss, by hand in float64."""
    dim, num_demo, num_agent, learning_rate, length = 2, 5, 4, 0.3, 3
    demo_x = RNG.normal(size=(num_demo, dim))
    agent_x = RNG.normal(size=(num_agent, dim))
    row_trajectory = np.array([0, 0, 1, 2, 2])
    theta = RNG.normal(size=dim)
    steps = RNG.normal(size=(3, 6, dim))  # 3 trajectories of 6 [s, a] rows
    trajectories = ranking.Trajectories(
        observations=jnp.asarray(steps[..., :1], jnp.float32),
        actions=jnp.asarray(steps[..., 1:], jnp.float32),
        lengths=jnp.array([6, 4, 6], jnp.int32),
        score=jnp.array([0.2, 0.9, 0.5]),
    )
    pairs = ranking.sample_pairs(jax.random.key(3), trajectories, 6, length)

    def softplus(v):
        return np.logaddexp(0, v)

    def sigmoid(v):
        return 1 / (1 + np.exp(-v))

    def numpy_outer(log_confidence):
        beta = np.exp(log_confidence)[row_trajectory]
        u = beta / beta.mean()
        # grad of mean_agent sp(-z) + mean_demo u sp(z) with z = theta . x
        grad = (-sigmoid(-agent_x @ theta)[:, None] * agent_x).mean(0)
        grad = grad + ((u * sigmoid(demo_x @ theta))[:, None] * demo_x).mean(0)
        lookahead = theta - learning_rate * grad
        rewards = softplus(-(steps @ lookahead))
        lengths = np.asarray(trajectories.lengths)

        def snippet(i, start):
            return rewards[i, start : min(start + length, lengths[i])].sum()

        worse = np.array(
            [snippet(i, s) for i, s in zip(pairs.worse, pairs.worse_start, strict=True)]
        )
        better = np.array(
            [snippet(i, s) for i, s in zip(pairs.better, pairs.better_start, strict=True)]
        )
        weight = np.asarray(pairs.weight, float)
        return np.sum(weight * softplus(worse - better)) / weight.sum()

    def inner_loss(params, log_confidence):
        beta = jnp.exp(log_confidence)[row_trajectory]
        u = beta / beta.mean()
        agent = jnp.mean(jax.nn.softplus(-(jnp.asarray(agent_x, jnp.float32) @ params)))
        demo = jnp.mean(u * jax.nn.softplus(jnp.asarray(demo_x, jnp.float32) @ params))
        return agent + demo

    inputs = jnp.concatenate([trajectories.observations, trajectories.actions], axis=-1)

    def outer(log_confidence):
        return ranking.cail_outer_loss(
            log_confidence, inner_loss, jnp.asarray(theta, jnp.float32), learning_rate,
            lambda params, x: jax.nn.softplus(-(x @ params)), inputs, trajectories, pairs,
            length,
        )[0]  # fmt: skip

    log_confidence = RNG.normal(size=3) * 0.5
    np.testing.assert_allclose(
        outer(jnp.asarray(log_confidence, jnp.float32)), numpy_outer(log_confidence), rtol=1e-5
    )
    gradient = jax.grad(outer)(jnp.asarray(log_confidence, jnp.float32))
    step = 1e-6
    numeric = [
        (numpy_outer(log_confidence + step * e) - numpy_outer(log_confidence - step * e))
        / (2 * step)
        for e in np.eye(3)
    ]
    np.testing.assert_allclose(gradient, numeric, rtol=1e-3, atol=1e-6)
