"""The offline methods' losses against NumPy computations of their formulas on random inputs,
their closed forms and the gradients that must (not) flow."""

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from pngail_jax.offline import losses

RNG = np.random.default_rng(0)


def _sigmoid(x):
    return 1 / (1 + np.exp(-x))


def test_dwbc_discriminator_loss_is_the_pu_risk_divided_by_eta():
    d_expert = RNG.uniform(0.1, 0.9, 64).astype(np.float32)
    d_other = RNG.uniform(0.1, 0.9, 64).astype(np.float32)
    eta = 0.5
    # The paper's form: eta E_E[-log d] + E_O[-log(1 - d)] - eta E_E[-log(1 - d)], over eta.
    paper = (
        eta * np.mean(-np.log(d_expert))
        + np.mean(-np.log(1 - d_other))
        - eta * np.mean(-np.log(1 - d_expert))
    ) / eta
    loss, metrics = losses.dwbc_discriminator_loss(d_expert, d_other, eta)
    np.testing.assert_allclose(loss, paper, rtol=1e-5)
    assert metrics["dwbc/disc_loss"] == loss


def test_dwbc_policy_loss_weights_against_numpy():
    nll_expert, nll_other = RNG.normal(size=(2, 32)).astype(np.float32)
    d_expert = RNG.uniform(0.1, 0.9, 32).astype(np.float32)
    d_other = RNG.uniform(0.1, 0.9, 32).astype(np.float32)
    alpha, eta = 7.5, 0.5
    weight_expert = eta / (d_expert * (1 - d_expert)) + 1
    weight_other = np.where(d_other >= 0.5, d_other / (1 - d_other), 0.0)
    expected = (
        alpha * nll_expert.mean()
        - np.mean(weight_expert * nll_expert)
        + np.mean(weight_other * nll_other)
    )
    loss, metrics = losses.dwbc_policy_loss(nll_expert, nll_other, d_expert, d_other, alpha, eta)
    np.testing.assert_allclose(loss, expected, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(metrics["dwbc/kept_other"], np.mean(d_other >= 0.5))


def test_dwbc_expert_weight_stays_positive_on_the_clipped_range():
    # alpha - w_E = 7.5 - 1 - eta / (d (1 - d)): smallest at d = 0.1 or 0.9, 6.5 - 0.5 / 0.09.
    d = jnp.array([0.1, 0.5, 0.9])
    gradient = jax.grad(
        lambda nll: losses.dwbc_policy_loss(nll, jnp.zeros(3), d, jnp.full(3, 0.2), 7.5, 0.5)[0]
    )(jnp.zeros(3))
    np.testing.assert_allclose(gradient * 3, [6.5 - 0.5 / 0.09, 6.5 - 2.0, 6.5 - 0.5 / 0.09], 1e-5)
    assert (gradient > 0).all()


def test_dwbc_policy_loss_sends_no_gradient_to_the_discriminator():
    def loss(d):
        return losses.dwbc_policy_loss(jnp.ones(4), jnp.ones(4), d, d, 7.5, 0.5)[0]

    assert not jnp.any(jax.grad(loss)(jnp.full(4, 0.6)))


def test_log_density_feature_clips_maps_and_stops_the_gradient():
    values = jnp.array([-50.0, -20.0, -5.0, 10.0, 30.0])
    np.testing.assert_allclose(losses.log_density_feature(values), [0, 0, 0.5, 1, 1], atol=1e-6)
    assert not jnp.any(jax.grad(lambda v: losses.log_density_feature(v).sum())(values))


def test_iswbc_discriminator_loss_is_logistic_regression():
    logits_expert, logits_union = RNG.normal(size=(2, 50)).astype(np.float32) * 3
    expected = np.mean(-np.log(_sigmoid(logits_expert))) + np.mean(
        -np.log(1 - _sigmoid(logits_union))
    )
    loss, _ = losses.iswbc_discriminator_loss(logits_expert, logits_union)
    np.testing.assert_allclose(loss, expected, rtol=1e-5)


def test_iswbc_weights_against_numpy_and_the_odds():
    logits = RNG.normal(size=100).astype(np.float32) * 2
    sigma = _sigmoid(logits.astype(np.float64))
    expected = 1 / (1 / (sigma + 1e-3) - 1 + 1e-3)
    np.testing.assert_allclose(losses.iswbc_weights(logits), expected, rtol=1e-4)
    # At D = 1/2 the odds are 1; the offsets make it 1 / (1 / 0.501 - 0.999) = 1.003001.
    np.testing.assert_allclose(losses.iswbc_weights(jnp.float32(0.0)), 1.003001, rtol=1e-5)
    np.testing.assert_allclose(losses.iswbc_log_odds(logits), -np.log(expected), rtol=1e-4)
    # Bounded: about 1e-3 where D -> 0, about 1e6 where D -> 1.
    np.testing.assert_allclose(losses.iswbc_weights(jnp.float32(-60.0)), 1 / 999.001, rtol=1e-3)
    assert 1e5 < float(losses.iswbc_weights(jnp.float32(60.0))) < 2e6


def test_one_centred_penalty_against_numpy():
    gradients = RNG.normal(size=(16, 5)).astype(np.float32)
    norms = np.linalg.norm(gradients + 1.1920929e-07, axis=-1)
    np.testing.assert_allclose(
        losses.one_centred_penalty(gradients), np.mean((norms - 1) ** 2), rtol=1e-5
    )
    # A unit gradient costs nothing (up to the offset).
    assert float(losses.one_centred_penalty(jnp.eye(5))) < 1e-10


@pytest.mark.parametrize("cutoff", [0.0, 0.8])
def test_weighted_nll_against_numpy(cutoff):
    nll = RNG.normal(size=40).astype(np.float32)
    weights = RNG.uniform(0, 2, 40).astype(np.float32)
    expected = np.mean(np.where(weights >= cutoff, weights, 0) * nll)
    loss, metrics = losses.weighted_nll(nll, weights, cutoff)
    np.testing.assert_allclose(loss, expected, rtol=1e-5, atol=1e-6)
    assert not jnp.any(jax.grad(lambda w: losses.weighted_nll(nll, w, cutoff)[0])(weights))


def test_iswbc_weights_at_the_optimal_discriminator_are_the_density_ratio():
    """A discrete problem: four (s, a) cells, the expert set E at probabilities p_E and the
    union U = 0.2 E + 0.8 S. The logistic loss of E against U, minimised over one free logit
    per cell, has its optimum at c = log(p_E / p_U), so ISW-BC's weight exp(-g(c)) is the
    density ratio p_E / p_U (up to its 1e-3 offsets), and a cell E never visits gets the
    floor, about 1e-3."""
    p_expert = np.array([0.5, 0.3, 0.2, 0.0])
    p_supplementary = np.array([0.1, 0.2, 0.3, 0.4])
    p_union = 0.2 * p_expert + 0.8 * p_supplementary
    # Batches whose empirical distributions are exactly p_E and p_U (10 and 50 rows).
    expert_cells = np.repeat(np.arange(4), (10 * p_expert).round().astype(int))
    union_cells = np.repeat(np.arange(4), (50 * p_union).round().astype(int))
    np.testing.assert_allclose(np.bincount(union_cells, minlength=4) / 50, p_union)

    def loss(logits):
        return losses.iswbc_discriminator_loss(logits[expert_cells], logits[union_cells])[0]

    optimizer = optax.adam(0.05)
    logits = jnp.zeros(4)
    state = optimizer.init(logits)

    @jax.jit
    def step(logits, state):
        updates, state = optimizer.update(jax.grad(loss)(logits), state)
        return logits + updates, state

    for _ in range(4000):
        logits, state = step(logits, state)
    weights = np.asarray(losses.iswbc_weights(logits))
    ratio = p_expert[:3] / p_union[:3]
    np.testing.assert_allclose(weights[:3], ratio, rtol=2e-2)
    assert weights[3] < 0.05  # never an expert cell: the optimum is c -> -inf


# -- ILID -----------------------------------------------------------------------------------


def _authors_selection(expert_like_next, expert_like, trajectory_ends, rollback):
    """ILID's codebase's selection, as it computes it on a whole buffer in time order: start
    from the rows whose next state is expert-like, then for k = 0..K-1 clear the first k + 1
    positions of every trajectory in the current-state mask and OR it in shifted by k + 1."""
    mask = expert_like_next.copy()
    for k in range(rollback):
        index = expert_like.copy()
        start = 0
        for end in trajectory_ends:
            index[start : min(end, start + k + 1)] = False
            start = end
        mask[: -(k + 1)] |= index[k + 1 :]
    return mask


@pytest.mark.parametrize("rollback", [1, 3, 20])
def test_ilid_selection_is_its_codebases_rollback_on_random_trajectories(rollback):
    """A row is selected when one of the next K states of its own trajectory is expert-like:
    the successor table and ``ilid_selection`` against the codebase's shifted masks, on
    trajectories of random lengths (the last row of each has no next state in the file, so
    its "next state" there is the next trajectory's first, which the codebase reads; rows
    whose K successors all lie within the trajectory are compared)."""
    from pngail_jax.demos import successor_rows

    lengths = RNG.integers(1, 30, size=12)
    ids = np.repeat(np.arange(12), lengths)
    expert_like = RNG.uniform(size=ids.size) < 0.15
    successors = successor_rows(ids, rollback)
    ours = np.asarray(losses.ilid_selection(jnp.asarray(expert_like), jnp.asarray(successors)))
    ends = np.cumsum(lengths)
    next_expert_like = np.r_[expert_like[1:], False]  # row t's next state is row t + 1
    theirs = _authors_selection(next_expert_like, expert_like, ends, rollback)
    position = np.arange(ids.size) - np.repeat(ends - lengths, lengths)
    within = position + rollback < np.repeat(lengths, lengths)  # all K successors inside
    np.testing.assert_array_equal(ours[within], theirs[within])
    # And directly from the definition, for every row.
    for row in range(ids.size):
        after = [
            r for r in range(row + 1, row + rollback + 1) if r < ids.size and ids[r] == ids[row]
        ]
        assert ours[row] == any(expert_like[r] for r in after)


def test_successor_rows_refuse_trajectories_that_are_not_contiguous():
    from pngail_jax.demos import successor_rows

    np.testing.assert_array_equal(
        successor_rows(np.array([0, 0, 0, 1, 1]), 2), [[1, 2], [2, -1], [-1, -1], [4, -1], [-1, -1]]
    )
    with pytest.raises(ValueError, match="each trajectory's rows together"):
        successor_rows(np.array([0, 1, 0]), 2)


def test_ilid_discriminator_loss_and_its_clipped_output_against_numpy():
    logits_p, logits_n = RNG.normal(0, 3, 64), RNG.normal(0, 3, 64)
    d_p = np.clip(_sigmoid(logits_p), 0.1, 0.9)
    d_n = np.clip(_sigmoid(logits_n), 0.1, 0.9)
    np.testing.assert_allclose(losses.clipped_probability(jnp.asarray(logits_p)), d_p, rtol=1e-6)
    loss, metrics = losses.ilid_discriminator_loss(jnp.asarray(d_p), jnp.asarray(d_n))
    np.testing.assert_allclose(loss, np.mean(-np.log(d_p) - np.log(1 - d_n)), rtol=1e-5)
    assert metrics["ilid/disc_loss"] == loss
