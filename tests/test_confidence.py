"""SC and BSC losses against NumPy evaluations of the formulas, and Table 1 on Pendulum."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import authors_data

from pngail_jax.confidence import ClassifierConfig, bsc_loss, logistic_loss, sc_loss
from pngail_jax.config.run_config import RunConfig
from pngail_jax.jobs.trainer_configs import adversarial_config

AUTHORS_PENDULUM = authors_data()


def f32(x):
    return jnp.asarray(x, jnp.float32)


def np_l(z):
    return np.log1p(np.exp(-z))


def np_sigmoid(z):
    return 1 / (1 + np.exp(-z))


def numpy_bsc(g_c, r, g_u, alpha, beta, eps):
    supervised = np.mean(r * np_l(g_c) + (1 - r) * np_l(-g_c))
    balance = alpha * (np.mean(np_l(g_u)) - np.mean(np_l(g_c))) + beta * (
        np.mean(np_l(-g_u)) - np.mean(np_l(-g_c))
    )
    return supervised + np.clip(balance, -eps, eps), balance


def numpy_bsc_gradient(g_c, r, g_u, alpha, beta, clip_active):
    """d/dg of eq. 13 by hand: l'(g) = -sigmoid(-g), d l(-g)/dg = sigmoid(g)."""
    n_c, n_u = len(g_c), len(g_u)
    grad_c = (r * -np_sigmoid(-g_c) + (1 - r) * np_sigmoid(g_c)) / n_c
    grad_u = np.zeros_like(g_u)
    if not clip_active:
        grad_c += (-alpha * -np_sigmoid(-g_c) - beta * np_sigmoid(g_c)) / n_c
        grad_u += (alpha * -np_sigmoid(-g_u) + beta * np_sigmoid(g_u)) / n_u
    return grad_c, grad_u


@pytest.fixture
def batch():
    rng = np.random.default_rng(0)
    return rng.normal(size=20), rng.uniform(size=20), rng.normal(size=80)


def test_logistic_loss():
    z = np.linspace(-30, 30, 13)
    np.testing.assert_allclose(logistic_loss(jnp.asarray(z)), np.logaddexp(0, -z), rtol=1e-6)


@pytest.mark.parametrize("eps", [10.0, 1e-4])  # clip inactive, clip active
def test_bsc_matches_numpy_with_gradients(batch, eps):
    g_c, r, g_u = batch
    alpha = beta = 0.8
    expected, balance = numpy_bsc(g_c, r, g_u, alpha, beta, eps)
    clip_active = abs(balance) > eps
    assert clip_active == (eps < 1)  # the two cases really are the two cases
    with jax.enable_x64(True):
        loss, metrics = bsc_loss(
            jnp.asarray(g_c), jnp.asarray(r), jnp.asarray(g_u), alpha, beta, eps
        )
        grad_c, grad_u = jax.grad(
            lambda c, u: bsc_loss(c, jnp.asarray(r), u, alpha, beta, eps)[0], argnums=(0, 1)
        )(jnp.asarray(g_c), jnp.asarray(g_u))
    np.testing.assert_allclose(loss, expected, rtol=1e-10)
    assert float(metrics["bsc/clip_active"]) == float(clip_active)
    expected_c, expected_u = numpy_bsc_gradient(g_c, r, g_u, alpha, beta, clip_active)
    np.testing.assert_allclose(grad_c, expected_c, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(grad_u, expected_u, rtol=1e-9, atol=1e-12)
    if clip_active:
        assert np.all(np.asarray(grad_u) == 0)  # no gradient through an active clip


def test_bsc_without_alpha_beta_is_the_supervised_term(batch):
    g_c, r, g_u = batch
    loss, metrics = bsc_loss(f32(g_c), f32(r), f32(g_u), 0.0, 0.0, 0.01)
    np.testing.assert_allclose(loss, np.mean(r * np_l(g_c) + (1 - r) * np_l(-g_c)), rtol=1e-6)
    np.testing.assert_allclose(loss, metrics["bsc/supervised"], rtol=1e-7)


@pytest.mark.parametrize("positive_branch", [True, False])
def test_sc_matches_numpy(batch, positive_branch):
    g_c, r, g_u = batch
    beta = 0.8
    if positive_branch:
        pos = np.mean((r - beta) * np_l(g_c)) + beta * np.mean(np_l(g_u))
        neg = np.mean((1 - r) * np_l(-g_c))
    else:
        pos = np.mean(r * np_l(g_c))
        neg = np.mean((1 - beta - r) * np_l(-g_c)) + beta * np.mean(np_l(-g_u))
    loss, metrics = sc_loss(
        jnp.asarray(g_c), jnp.asarray(r), jnp.asarray(g_u), beta, positive_branch
    )
    np.testing.assert_allclose(loss, max(pos, 0) + max(neg, 0), rtol=1e-5)
    np.testing.assert_allclose(metrics["sc/positive_risk"], pos, rtol=1e-5)
    np.testing.assert_allclose(metrics["sc/negative_risk"], neg, rtol=1e-5)


@pytest.mark.parametrize("positive_branch", [True, False])
def test_masked_unlabelled_rows_drop_out_of_both_losses(batch, positive_branch):
    """A batch of static width whose last rows are masked (weights 1/k on the first k, 0
    after) is the loss on the first k rows: how one grid holds several label ratios, each
    with the authors' int(n_u / n_c) unlabelled rows per step."""
    g_c, r, g_u = batch
    k, beta = 9, 0.9
    weights = np.where(np.arange(len(g_u)) < k, 1 / k, 0.0)
    garbage = g_u.copy()
    garbage[k:] = 1e3  # masked rows may hold anything
    with jax.enable_x64(True):
        bsc, _ = bsc_loss(*map(jnp.asarray, (g_c, r, garbage)), beta, beta, 10.0, weights)
        sc, _ = sc_loss(*map(jnp.asarray, (g_c, r, garbage)), beta, positive_branch, weights)
    np.testing.assert_allclose(bsc, numpy_bsc(g_c, r, g_u[:k], beta, beta, 10.0)[0], rtol=1e-10)
    expected_sc, _ = sc_loss(*map(jnp.asarray, (g_c, r, g_u[:k])), beta, positive_branch)
    np.testing.assert_allclose(sc, expected_sc, rtol=1e-6)


def test_the_classifier_batch_holds_int_nu_over_nc_unlabelled_rows():
    """The authors' code draws int(n_u / n_c) unlabelled rows per labelled row: 4, 9, 19, 32
    at label ratios 0.2, 0.1, 0.05, 0.03 of 1,000 rows; a sweep's batch is as wide as its
    smallest ratio needs, and a fixed size stays fixed."""
    config = ClassifierConfig()
    counts = [config.unlabelled_rows_per_step(1000, round(ratio * 1000)) for ratio in RATIOS]
    assert counts == [4, 9, 19, 32]
    assert ClassifierConfig(unlabelled_batch_size=4).unlabelled_rows_per_step(1000, 50) == 4
    run = RunConfig(label_ratios=(0.2, 0.05))
    assert adversarial_config(run, 1000).classifier.unlabelled_batch_width == 19
    assert adversarial_config(RunConfig(), 1000).classifier.unlabelled_batch_width == 4


RATIOS = (0.2, 0.1, 0.05, 0.03)


def test_sc_non_negative_correction_zeroes_a_negative_risk():
    # All labelled confidences 1 and large positive logits: pos = mean (1 - beta) l(g) + ...,
    # tiny; neg = mean (1 - beta - 1) l(-g) + beta mean_u l(-g) with l(-g) large on D_c and
    # the unlabelled logits large too: the negative branch's risk is beta (l_u - l_c) < 0
    # when D_c's logits exceed D_u's, and is clipped at 0.
    g_c, g_u, r = jnp.full(4, 5.0), jnp.full(4, 1.0), jnp.ones(4)
    loss, metrics = sc_loss(g_c, r, g_u, 0.8, False)
    assert metrics["sc/negative_risk"] < 0
    np.testing.assert_allclose(loss, max(float(metrics["sc/positive_risk"]), 0.0), rtol=1e-6)


@pytest.mark.skipif(
    not (AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy").exists(),
    reason=f"the authors' Pendulum set is not in {AUTHORS_PENDULUM}",
)
def test_table1_pendulum_bsc_beats_sc():
    """Label ratio 0.2, 5 seeds, the reference's 25,000 steps (paper: BSC 0.097, SC 0.126).

    Actions in the environment's units (the file's known scale, x 2, applied by default).
    Measured here: BSC 0.093 +- 0.005, SC 0.132 +- 0.003 (about 11 s for all 10 runs)."""
    from pngail_jax.programs import classify

    summary = classify.main(
        ["--demos", str(AUTHORS_PENDULUM / "Pendulum-v1_mixture.npy"), "--seeds", "5"]
    )
    assert summary["bsc"]["mae_mean"] <= 0.11, summary
    assert summary["bsc"]["mae_mean"] < summary["sc"]["mae_mean"], summary


def test_risk_estimator_variance_matches_the_bootstrap_formula():
    """alpha = beta = 0 leaves the supervised mean over D_c: variance ~ Var(row loss) / n_c."""
    from pngail_jax.confidence import risk_estimator_variance

    rng = np.random.default_rng(0)
    logits = rng.normal(size=500)
    confidence = rng.uniform(size=500)
    labelled = np.arange(500) < 100
    row_loss = (confidence * np_l(logits) + (1 - confidence) * np_l(-logits))[:100]
    variance = risk_estimator_variance(
        f32(logits),
        f32(confidence),
        jnp.asarray(labelled),
        0.0,
        jax.random.key(0),
        num_resamples=4000,
    )
    np.testing.assert_allclose(variance, row_loss.var() / 100, rtol=0.1)
    # With alpha = beta > 0 the unlabelled rows add their own term: the variance changes.
    balanced = risk_estimator_variance(
        f32(logits),
        f32(confidence),
        jnp.asarray(labelled),
        0.8,
        jax.random.key(0),
        num_resamples=4000,
    )
    assert not np.isclose(balanced, variance, rtol=0.1)


def test_split_and_train_labels_only_allowed_rows(monkeypatch):
    """``allowed`` reaches the split: the classifier is given labels only on allowed rows."""
    from pngail_jax import confidence as confidence_module
    from pngail_jax.confidence import ClassifierConfig, ClassifierSpec, split_and_train

    def labels_seen(config, spec, inputs, confidence, labelled, key):
        # In place of training (seconds of compilation): predict each row's own input column,
        # 1 for rows outside the mask, so MAE over D_u would show any labelled such row.
        metrics = {"bsc/clip_active": jnp.zeros(config.num_steps)}
        return inputs[:, 0], inputs[:, 0], metrics

    monkeypatch.setattr(confidence_module, "train_classifier", labels_seen)
    monkeypatch.setattr(confidence_module, "risk_estimator_variance", lambda *_: jnp.zeros(()))
    allowed = np.arange(30) % 3 == 0  # 10 allowed rows
    inputs = jnp.asarray(np.stack([~allowed, np.zeros(30)], axis=1), jnp.float32)
    run = jax.jit(
        jax.vmap(
            lambda key, mask: split_and_train(
                ClassifierConfig(num_steps=2), ClassifierSpec.bsc(), inputs, jnp.zeros(30), 30,
                0.3, 0.0, key, allowed=mask,
            ),
            in_axes=(0, None),
        )
    )  # fmt: skip
    keys = jax.random.split(jax.random.key(0), 4)
    # MAE over D_u of |marker - 0|: the 20 rows outside the mask are all unlabelled, so the
    # mean is 20 / 21 with 9 of 30 labelled (round(0.3 * 30)), whatever the draw.
    np.testing.assert_allclose(run(keys, jnp.asarray(allowed))["mae"], 20 / 21, rtol=1e-6)
    unmasked = run(keys, jnp.ones(30, bool))["mae"]
    assert np.all(np.asarray(unmasked) < 20 / 21)  # without the mask, some are labelled


def test_both_classifiers_learn_a_known_confidence_and_bsc_learns_it_better():
    """Rows x ~ N(0, I_4) whose confidence is a known function of them, r(x) = sigmoid(4 (x_0
    + x_1 / 2 - 0.3)) (23% of the rows above 0.9, 41% below 0.1), 500 rows of which
    100 labelled (label ratio 0.2), 3,000 steps of the reference's batches; 3 seeds, SC and
    BSC with the same seeds in one program. A classifier that learned nothing predicts the
    labelled rows' mean confidence (MAE 0.36-0.38 on these draws). Measured here on 6
    seeds: SC 0.16-0.21, BSC 0.022-0.027 (so the paper's Table 1 ordering without its
    files). The bars: each MAE below 0.75 x the constant predictor's, BSC below SC on every
    seed."""
    from pngail_jax.confidence import ClassifierSpec, confidence_errors, train_classifier

    num_rows, num_seeds = 500, 3
    rng = np.random.default_rng(0)
    inputs = rng.normal(size=(num_seeds, num_rows, 4)).astype(np.float32)
    confidence = np_sigmoid(4 * (inputs[..., 0] + 0.5 * inputs[..., 1] - 0.3)).astype(np.float32)
    labelled = np.zeros((num_seeds, num_rows), bool)
    for seed in range(num_seeds):
        labelled[seed, rng.choice(num_rows, num_rows // 5, replace=False)] = True
    config = ClassifierConfig(num_steps=3000)

    def mae(spec, x, r, mask, key):
        predicted, _, _ = train_classifier(config, spec, x, r, mask, key)
        return confidence_errors(predicted, r, mask)["mae"]

    keys = jax.random.split(jax.random.key(0), num_seeds)
    per_seed = jax.jit(jax.vmap(mae, in_axes=(None, 0, 0, 0, 0)))
    sc = np.asarray(per_seed(ClassifierSpec.sc(), inputs, confidence, labelled, keys))
    bsc = np.asarray(per_seed(ClassifierSpec.bsc(), inputs, confidence, labelled, keys))
    constant = np.array(
        [
            np.abs(r[~mask] - r[mask].mean()).mean()
            for r, mask in zip(confidence, labelled, strict=True)
        ]
    )
    assert (sc < 0.75 * constant).all(), (sc, constant)
    assert (bsc < 0.75 * constant).all(), (bsc, constant)
    assert (bsc < sc).all(), (bsc, sc)
