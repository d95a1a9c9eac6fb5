"""The appendix baselines' losses against independent NumPy computations of their formulas:
T-REX's Bradley-Terry loss on snippet sums, BC, CAIL's outer loss (f-IRL's: tests/test_firl.py)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pngail_jax.adversarial import bc, ranking

RNG = np.random.default_rng(0)
# Compiled once per shape: op-by-op, the pair draws cost seconds each.
sample_pairs = jax.jit(ranking.sample_pairs, static_argnums=(2, 3))


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
    pairs = sample_pairs(jax.random.key(1), trajectories, num_pairs, length)
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


TINY_TREX = ranking.RankingConfig(
    num_steps=300, snippet_length=5, hidden_sizes=(16,), learning_rate=1e-2, l2_coef=1e-4
)
TINY_DREX = dataclasses.replace(
    ranking.DrexConfig().ranking, num_steps=300, pairs_per_step=16, num_dataset_pairs=100,
    snippet_length=5, hidden_sizes=(16,), learning_rate=1e-2, l2_coef=1e-4, min_score_margin=2,
)  # fmt: skip


@pytest.mark.parametrize("config", [TINY_TREX, TINY_DREX], ids=["trex", "drex"])
def test_ranking_rewards_learn_to_rank_the_trajectories(config):
    # Trajectory k visits states around k: the better-scored, the larger the state.
    observations = np.stack([np.full((20, 1), k, np.float32) for k in range(4)])
    observations += RNG.normal(scale=0.1, size=observations.shape).astype(np.float32)
    trajectories = ranking.Trajectories(
        observations=jnp.asarray(observations),
        actions=jnp.zeros((4, 20, 1)),
        lengths=jnp.full(4, 20, jnp.int32),
        score=jnp.arange(4.0),
    )
    params, metrics = ranking.train_ranking_reward(config, trajectories, jax.random.key(0))
    assert jax.tree.leaves(params)[0].shape[0] == config.num_members
    reward = ranking.RankingReward(config.hidden_sizes)
    returns = reward.ensemble(params, trajectories.observations).sum(1)
    assert np.all(np.diff(np.asarray(returns)) > 0)  # the learned reward orders them
    # Above the entropy of the label flips, which no reward can beat, the loss halves.
    p = config.label_flip_probability
    floor = 0.0 if p == 0 else -(p * np.log(p) + (1 - p) * np.log(1 - p))
    excess = np.asarray(metrics["ranking/loss"]) - floor  # float[M, num_steps]
    assert np.all(excess[:, -50:].mean(1) < excess[:, :50].mean(1) / 2)


def test_ranking_reward_loss_is_cross_entropy_plus_l2_against_numpy():
    num_trajectories, steps, length, num_pairs, l2_coef = 4, 9, 3, 7, 0.01
    observations = RNG.normal(size=(num_trajectories, steps, 2)).astype(np.float32)
    trajectories = ranking.Trajectories(
        observations=jnp.asarray(observations),
        actions=jnp.zeros((num_trajectories, steps, 1)),
        lengths=jnp.array([9, 9, 2, 9], jnp.int32),
        score=jnp.array([0.0, -0.4, -0.8, 0.3]),
    )
    reward = ranking.RankingReward((5, 4))
    params = reward.init(jax.random.key(0), 2)
    pairs = sample_pairs(jax.random.key(1), trajectories, num_pairs, length)
    loss, metrics = jax.jit(ranking.reward_loss, static_argnums=(0, 4))(
        reward, params, trajectories, pairs, length, l2_coef
    )

    layers = [params["params"][f"Dense_{i}"] for i in range(3)]

    def r(states):  # ReLU, ReLU, linear output without a bias
        hidden = states
        for layer in layers[:-1]:
            hidden = np.maximum(hidden @ np.asarray(layer["kernel"]) + np.asarray(layer["bias"]), 0)
        return (hidden @ np.asarray(layers[-1]["kernel"]))[..., 0]

    lengths = np.asarray(trajectories.lengths)

    def snippet(index, start):
        return r(observations[index, start : min(start + length, lengths[index])]).sum()

    zipped = zip(pairs.worse, pairs.worse_start, pairs.better, pairs.better_start, strict=True)
    sums = np.array([[snippet(w, ws), snippet(b, bs)] for w, ws, b, bs in zipped], np.float64)
    # torch's CrossEntropyLoss on logits [R_worse, R_better] with the label "better"
    cross_entropy = -(sums[:, 1] - np.log(np.exp(sums).sum(axis=1)))
    weight = np.asarray(pairs.weight, np.float64)
    squares = sum(np.sum(np.asarray(leaf, np.float64) ** 2) for leaf in jax.tree.leaves(params))
    expected = np.sum(weight * cross_entropy) / weight.sum() + l2_coef * squares
    assert "bias" not in layers[-1] and weight.sum() > 0
    np.testing.assert_allclose(loss, expected, rtol=1e-5)
    np.testing.assert_allclose(metrics["ranking/l2"], l2_coef * squares, rtol=1e-5)


def noise_level_trajectories(levels, steps=60):
    """One trajectory per noise level, scored by minus the level (D-REX's rankings)."""
    num = len(levels)
    return ranking.Trajectories(
        observations=jnp.zeros((num, steps, 1)),
        actions=jnp.zeros((num, steps, 1)),
        lengths=jnp.full(num, steps, jnp.int32).at[-1].set(30),
        score=-jnp.asarray(levels, jnp.float32),
    )


def test_pairs_come_only_from_eligible_trajectories_uniformly():
    trajectories = noise_level_trajectories(np.linspace(0, 1, 6))
    eligible = jnp.array([True, False, True, True, False, True])
    pairs = sample_pairs(jax.random.key(0), trajectories, 12_000, 40, eligible)
    drawn = np.concatenate([pairs.worse, pairs.better])
    assert set(drawn.tolist()) == {0, 2, 3, 5}
    # Uniform with replacement: each of the 4 x 4 ordered pairs (self-pairs too) 1/16 of the
    # draws, order within a pair by score; self-pairs have weight 0.
    counts = np.zeros((6, 6))
    np.add.at(counts, (np.asarray(pairs.worse), np.asarray(pairs.better)), 1)
    unordered = counts + counts.T - np.diag(np.diag(counts))
    expected = np.array([1 / 16 if i == j else 2 / 16 for i in range(4) for j in range(4)])
    seen = unordered[np.ix_([0, 2, 3, 5], [0, 2, 3, 5])].ravel() / 12_000
    np.testing.assert_allclose(seen, expected, atol=0.012)
    same = np.asarray(pairs.worse) == np.asarray(pairs.better)
    np.testing.assert_array_equal(np.asarray(pairs.weight), (~same).astype(np.float32))
    # The last trajectory has 30 steps, fewer than 40: its snippets start at 0.
    better = np.asarray(pairs.better)
    assert np.all(np.asarray(pairs.better_start)[better == 5] == 0)


def test_drex_pairs_are_noise_levels_at_least_the_margin_apart():
    config = ranking.DrexConfig()
    assert config.noise_levels == tuple(np.round(np.arange(0, 1.0, 0.05), 2))
    trajectories = noise_level_trajectories(config.noise_levels)
    pairs = sample_pairs(
        jax.random.key(2), trajectories, 20_000, 50, None, config.ranking.min_score_margin
    )
    levels = -np.asarray(trajectories.score)
    worse, better = levels[np.asarray(pairs.worse)], levels[np.asarray(pairs.better)]
    assert np.all(worse - better >= 0.3 - 1e-6)  # less noise ranked better, 0.3 apart or more
    np.testing.assert_array_equal(pairs.weight, 1.0)
    # Every one of the C(20, 2) level pairs with a nominal gap >= 0.3 appears: 105 of them
    # (the CAIL codebase's float64 check drops 0.6 / 0.9, 0.9 - 0.6 < 0.3: 104 there).
    assert len(set(zip(worse.round(2), better.round(2), strict=True))) == 105
    # None allowed (a margin wider than any gap): every weight is 0.
    none = sample_pairs(jax.random.key(3), trajectories, 8, 50, None, 2.0)
    np.testing.assert_array_equal(none.weight, 0.0)


def test_labels_flip_at_the_stated_rate():
    trajectories = noise_level_trajectories(np.linspace(0, 1, 5))
    pairs = sample_pairs(jax.random.key(4), trajectories, 10_000, 10, None, 0.3)
    flipped = jax.jit(ranking.flip_labels)(jax.random.key(5), pairs, 0.1)
    swapped = np.asarray(flipped.worse) != np.asarray(pairs.worse)
    assert abs(swapped.mean() - 0.1) < 0.01  # binomial std 0.003
    np.testing.assert_array_equal(np.asarray(flipped.better)[swapped], pairs.worse[swapped])
    np.testing.assert_array_equal(
        np.asarray(flipped.better_start)[swapped], pairs.worse_start[swapped]
    )
    np.testing.assert_array_equal(np.asarray(flipped.worse)[~swapped], pairs.worse[~swapped])


def test_trex_draws_only_eligible_trajectories_long_enough_for_its_snippets():
    trajectories = noise_level_trajectories([0.0, 0.2, 0.4, 0.6])  # the last: 30 steps
    eligible = jnp.array([True, False, True, True])
    drawable = ranking.drawable_trajectories(ranking.RankingConfig(), trajectories, eligible)
    np.testing.assert_array_equal(drawable, [True, False, True, False])  # 30 < 40 steps
    drex = ranking.DrexConfig().ranking  # D-REX takes a shorter trajectory whole
    assert ranking.drawable_trajectories(drex, trajectories, None) is None
    np.testing.assert_array_equal(
        ranking.drawable_trajectories(drex, trajectories, eligible), eligible
    )


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


def test_deterministic_bc_reaches_a_small_mse_on_a_linear_target():
    # Actions a = obs @ W within the bounds [-2, 2]; the BC loss against its formula, then
    # D-REX's settings but a smaller network and fewer steps.
    observations = RNG.uniform(-1, 1, size=(512, 3)).astype(np.float32)
    actions = observations @ np.array([[0.8, -0.4], [0.3, 0.5], [-0.6, 0.2]], np.float32)
    low, high = jnp.full(2, -2.0), jnp.full(2, 2.0)
    config = bc.DeterministicBCConfig(num_steps=1_500, hidden_sizes=(64, 64))
    params, metrics = jax.jit(bc.train_deterministic_bc, static_argnums=0)(
        config, jnp.asarray(observations), jnp.asarray(actions), low, high, jax.random.key(0)
    )
    predicted = np.asarray(bc.cloned_actions(config, params, observations, low, high))
    mse = np.mean((predicted - actions) ** 2)
    assert mse < 0.02 * np.var(actions)  # in the environment's units
    unit_predicted, unit_actions = predicted / 2, actions / 2  # the loss's [-1, 1] units
    squares = sum(np.sum(np.asarray(leaf, np.float64) ** 2) for leaf in jax.tree.leaves(params))
    loss, _ = bc.deterministic_bc_loss(
        jnp.asarray(unit_predicted), jnp.asarray(unit_actions), params, config.l2_coef
    )
    expected = np.mean((unit_predicted - unit_actions) ** 2) + 1e-3 * squares
    np.testing.assert_allclose(loss, expected, rtol=1e-5)
    assert metrics["bc/mse"][-100:].mean() < metrics["bc/mse"][:100].mean() / 10
