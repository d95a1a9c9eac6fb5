"""Semi-supervised confidence classifiers: SC (2IWIL) and BSC (PN-GAIL, eq. 13).

A classifier g maps a demonstration pair x = [s, a] to a logit; sigmoid(g(x)) is the predicted
confidence that x is optimal. Training sees labelled rows D_c (with confidence r) and
unlabelled rows D_u. ``l(z) = softplus(-z)`` is the logistic loss and
``alpha = beta = n_u / (n_c + n_u)`` (``docs/demonstrations.md`` gives both losses).

Which classifier runs is data (``ClassifierSpec.bsc_coef``), so SC and BSC train side by side
in one vmapped program.
"""

from __future__ import annotations

import functools

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax
from flax import struct

from pngail_jax.config.classifier import DEFAULT_BSC_EPS, ClassifierConfig
from pngail_jax.networks import OUTPUT_SCALE, torch_like_init


def logistic_loss(z: jax.Array) -> jax.Array:
    """l(z) = log(1 + exp(-z)) = softplus(-z), elementwise."""
    return jax.nn.softplus(-z)


def _unlabelled_mean(values, weights):
    """mean_u: the plain mean, or ``sum(weights * values)`` for weights float[n_u] that sum
    to 1 (a batch whose last rows are masked out)."""
    return jnp.mean(values) if weights is None else jnp.sum(weights * values)


def bsc_loss(
    logits_labelled, confidence, logits_unlabelled, alpha, beta, eps, unlabelled_weights=None
):
    """Balanced semi-conf risk, eq. 13 with the clip of appendix C.2.

    ``R_C + clip(R_1, -eps, eps)`` with ``R_C = mean_c[r l(g) + (1 - r) l(-g)]`` and
    ``R_1 = alpha (mean_u l(g) - mean_c l(g)) + beta (mean_u l(-g) - mean_c l(-g))``. When
    ``|R_1| > eps`` the clip passes no gradient to it.

    Args: logits_labelled float[n_c], confidence float[n_c], logits_unlabelled float[n_u],
    unlabelled_weights float[n_u] summing to 1 (None: equal), the weights of ``mean_u``.
    Returns ``(loss, metrics)``.
    """
    supervised = jnp.mean(
        confidence * logistic_loss(logits_labelled)
        + (1 - confidence) * logistic_loss(-logits_labelled)
    )
    mean_u = functools.partial(_unlabelled_mean, weights=unlabelled_weights)
    balance = alpha * (
        mean_u(logistic_loss(logits_unlabelled)) - jnp.mean(logistic_loss(logits_labelled))
    ) + beta * (
        mean_u(logistic_loss(-logits_unlabelled)) - jnp.mean(logistic_loss(-logits_labelled))
    )
    loss = supervised + jnp.clip(balance, -eps, eps)
    return loss, {
        "bsc/supervised": supervised,
        "bsc/balance": balance,
        "bsc/clip_active": (jnp.abs(balance) > eps).astype(loss.dtype),
    }


def sc_loss(
    logits_labelled, confidence, logits_unlabelled, beta, positive_branch, unlabelled_weights=None
):
    """Semi-conf risk of 2IWIL (eq. 2) with its code's non-negative correction.

    ``positive_branch`` (bool[]) is whether the mean *labelled* confidence exceeds 0.5 (the
    reference decides with the hidden unlabelled confidences; we use what is known):
      True:  pos = mean_c (r - beta) l(g) + beta mean_u l(g),  neg = mean_c (1 - r) l(-g)
      False: pos = mean_c r l(g),  neg = mean_c (1 - beta - r) l(-g) + beta mean_u l(-g)
    loss = max(pos, 0) + max(neg, 0). ``unlabelled_weights`` as in ``bsc_loss``. Returns
    ``(loss, metrics)``.
    """
    l_pos_c, l_neg_c = logistic_loss(logits_labelled), logistic_loss(-logits_labelled)
    l_pos_u, l_neg_u = logistic_loss(logits_unlabelled), logistic_loss(-logits_unlabelled)
    mean_u = functools.partial(_unlabelled_mean, weights=unlabelled_weights)
    positive_pos = jnp.mean((confidence - beta) * l_pos_c) + beta * mean_u(l_pos_u)
    positive_neg = jnp.mean((1 - confidence) * l_neg_c)
    negative_pos = jnp.mean(confidence * l_pos_c)
    negative_neg = jnp.mean((1 - beta - confidence) * l_neg_c) + beta * mean_u(l_neg_u)
    pos = jnp.where(positive_branch, positive_pos, negative_pos)
    neg = jnp.where(positive_branch, positive_neg, negative_neg)
    loss = jnp.maximum(pos, 0.0) + jnp.maximum(neg, 0.0)
    return loss, {"sc/positive_risk": pos, "sc/negative_risk": neg}


class ConfidenceClassifier(nn.Module):
    """The reference's classifier: MLP 40-40 tanh with dropout 0.5 after each hidden layer."""

    hidden_sizes: tuple[int, ...] = (40, 40)
    dropout_rate: float = 0.5

    @nn.compact
    def __call__(self, x: jax.Array, deterministic: bool) -> jax.Array:
        """x float[..., obs_size + action_size] -> logit float[...]."""
        for size in self.hidden_sizes:
            x = jnp.tanh(nn.Dense(size, kernel_init=torch_like_init())(x))
            x = nn.Dropout(self.dropout_rate, deterministic=deterministic)(x)
        logit = nn.Dense(1, kernel_init=torch_like_init(OUTPUT_SCALE))(x)
        return logit[..., 0]


@struct.dataclass
class ClassifierSpec:
    """Which classifier (``bsc_coef`` 1 = BSC, 0 = SC) and its eps: pytree leaves."""

    bsc_coef: jax.Array
    eps: jax.Array

    @classmethod
    def sc(cls) -> ClassifierSpec:
        return cls(bsc_coef=jnp.asarray(0.0), eps=jnp.asarray(DEFAULT_BSC_EPS))

    @classmethod
    def bsc(cls, eps: float = DEFAULT_BSC_EPS) -> ClassifierSpec:
        if not eps > 0:
            raise ValueError(f"BSC eps must be positive, got {eps!r}")
        return cls(bsc_coef=jnp.asarray(1.0), eps=jnp.asarray(eps, jnp.float32))


def _unlabelled_weights(config: ClassifierConfig, num_rows: int, num_labelled: jax.Array):
    """float[width] weights of ``mean_u`` over the unlabelled batch: 1/k on its first k =
    ``labelled_batch_size * (n_u // n_c)`` rows (the authors' count, at most the width), 0
    after; None (a plain mean) when the config fixes the count."""
    if config.unlabelled_batch_size is not None:
        return None
    width = config.unlabelled_batch_width
    ratio = (num_rows - num_labelled) // jnp.maximum(num_labelled, 1)
    rows_per_step = jnp.clip(config.labelled_batch_size * ratio, 1, width)
    return (jnp.arange(width) < rows_per_step) / rows_per_step


def train_classifier(
    config: ClassifierConfig,
    spec: ClassifierSpec,
    inputs: jax.Array,
    confidence: jax.Array,
    labelled: jax.Array,
    key: jax.Array,
):
    """Trains one classifier; pure, so ``vmap`` runs seeds x variants at once.

    Args:
      inputs: float[N, d] rows [s, a] (all of D_c and D_u; rows outside the split have
        ``labelled`` False and are treated as unlabelled, so callers pass only the split).
      confidence: float[N], the labels the learner may see (only read where ``labelled``).
      labelled: bool[N], the D_c mask. alpha = beta = n_u / (n_c + n_u) follow from it.
      key: draws the initialisation, dropout and batches.

    Returns ``(predicted, logits, metrics)``: predicted confidence float[N], sigmoid(g(x))
    for unlabelled rows and the given label for labelled rows; the trained g(x) float[N]
    (no dropout); metrics float[num_steps] each.
    """
    model = ConfidenceClassifier(config.hidden_sizes, config.dropout_rate)
    init_key, train_key = jax.random.split(key)
    params = model.init(init_key, inputs[0], deterministic=True)
    optimizer = optax.amsgrad(config.learning_rate)
    beta, unlabelled_weights, positive_branch, labelled_p, unlabelled_p = _training_constants(
        config, confidence, labelled
    )
    width = config.unlabelled_batch_width

    def loss_fn(params, batch_labelled, batch_unlabelled, dropout_key):
        key_c, key_u = jax.random.split(dropout_key)
        logits_c = model.apply(
            params, inputs[batch_labelled], deterministic=False, rngs={"dropout": key_c}
        )
        logits_u = model.apply(
            params, inputs[batch_unlabelled], deterministic=False, rngs={"dropout": key_u}
        )
        r = confidence[batch_labelled]
        bsc, bsc_metrics = bsc_loss(logits_c, r, logits_u, beta, beta, spec.eps, unlabelled_weights)
        sc, sc_metrics = sc_loss(logits_c, r, logits_u, beta, positive_branch, unlabelled_weights)
        loss = spec.bsc_coef * bsc + (1 - spec.bsc_coef) * sc
        return loss, {"loss": loss, "bsc/clip_active": bsc_metrics["bsc/clip_active"]}

    def step(carry, step_key):
        params, optimizer_state = carry
        key_c, key_u, dropout_key = jax.random.split(step_key, 3)
        batch_c = jax.random.choice(
            key_c, inputs.shape[0], (config.labelled_batch_size,), p=labelled_p
        )
        batch_u = jax.random.choice(key_u, inputs.shape[0], (width,), p=unlabelled_p)
        grads, metrics = jax.grad(loss_fn, has_aux=True)(params, batch_c, batch_u, dropout_key)
        updates, optimizer_state = optimizer.update(grads, optimizer_state, params)
        return (optax.apply_updates(params, updates), optimizer_state), metrics

    (params, _), metrics = jax.lax.scan(
        step, (params, optimizer.init(params)), jax.random.split(train_key, config.num_steps)
    )
    logits = model.apply(params, inputs, deterministic=True)
    return jnp.where(labelled, confidence, jax.nn.sigmoid(logits)), logits, metrics


def _training_constants(config: ClassifierConfig, confidence, labelled):
    """What a classifier's training reads of its split: beta = n_u / N, the unlabelled rows'
    weights, SC's branch (the labelled mean above 0.5), and the labelled and unlabelled rows'
    sampling probabilities float[N]."""
    num_rows, num_labelled = labelled.shape[0], labelled.sum()
    beta = (num_rows - num_labelled) / num_rows
    unlabelled_weights = _unlabelled_weights(config, num_rows, num_labelled)
    positive_branch = jnp.sum(jnp.where(labelled, confidence, 0.0)) / num_labelled > 0.5
    labelled_p = labelled / num_labelled
    unlabelled_p = (~labelled) / jnp.maximum((~labelled).sum(), 1)
    return beta, unlabelled_weights, positive_branch, labelled_p, unlabelled_p


def confidence_errors(predicted, true_confidence, labelled):
    """MAE and RMSE over the unlabelled rows only (Table 1): a dict of float[]."""
    unlabelled = ~labelled
    errors = jnp.where(unlabelled, predicted - true_confidence, 0.0)
    count = jnp.maximum(unlabelled.sum(), 1)
    return {"mae": jnp.abs(errors).sum() / count, "rmse": jnp.sqrt((errors**2).sum() / count)}


def split_and_train(
    config: ClassifierConfig,
    spec: ClassifierSpec,
    inputs: jax.Array,
    confidence: jax.Array,
    traj_size: int,
    label_ratio,
    noise_std,
    key: jax.Array,
    allowed: jax.Array | None = None,
) -> dict[str, jax.Array]:
    """One seed of Table 1: draw the split, train, score the unlabelled rows.

    The seed's key draws the rows, the split, the noise, the initialisation, dropout and
    batches, so SC and BSC run with the same key see the same split. ``allowed`` (bool[N],
    None = all) marks the rows whose confidence may be labelled (``make_split``). Returns
    float[] metrics:
    ``mae``, ``rmse`` and ``clip_active`` (fraction of steps where BSC's clip was active; also
    computed, unused, for SC).
    """
    from pngail_jax.demos import make_split

    split_key, train_key = jax.random.split(key)
    split = make_split(split_key, confidence, traj_size, label_ratio, noise_std, allowed)
    variance_key = jax.random.fold_in(key, 1)  # leaves the training draws as they were
    predicted, logits, metrics = train_classifier(
        config, spec, inputs[split.indices], split.confidence, split.labelled, train_key
    )
    errors = confidence_errors(predicted, split.true_confidence, split.labelled)
    beta = 1.0 - split.labelled.mean()
    variances = {
        f"variance_{name}": risk_estimator_variance(
            logits, split.confidence, split.labelled, coefficient, variance_key
        )
        for name, coefficient in (("origin", 0.0), ("balanced", beta))
    }
    return {**errors, **variances, "clip_active": metrics["bsc/clip_active"].mean()}


def risk_estimator_variance(
    logits, confidence, labelled, alpha_beta, key, num_resamples: int = 1000
):
    """Variance of the empirical BSC risk (eq. 13, unclipped) of a fixed classifier (Table 5).

    Resamples D_c and D_u with replacement at their own sizes (a bootstrap of the estimator
    of Theorem 4.2 with n_c and n_u fixed) and evaluates ``R_C + R_1`` with
    ``alpha = beta = alpha_beta``; ``alpha_beta = 0`` is the paper's "origin". Returns float[].
    """
    num_rows = logits.shape[0]
    num_labelled = labelled.sum()
    labelled_p = labelled / num_labelled
    unlabelled_p = (~labelled) / jnp.maximum(num_rows - num_labelled, 1)
    # Shapes must be static: draw num_rows rows from each set and weight the first n_c (or
    # n_u) of them, so each resample has exactly the set's own size.
    weights_c = (jnp.arange(num_rows) < num_labelled) / num_labelled
    weights_u = (jnp.arange(num_rows) < num_rows - num_labelled) / (num_rows - num_labelled)

    def one(resample_key):
        key_c, key_u = jax.random.split(resample_key)
        rows_c = jax.random.choice(key_c, num_rows, (num_rows,), p=labelled_p)
        rows_u = jax.random.choice(key_u, num_rows, (num_rows,), p=unlabelled_p)
        g_c, r, g_u = logits[rows_c], confidence[rows_c], logits[rows_u]
        supervised = jnp.sum(weights_c * (r * logistic_loss(g_c) + (1 - r) * logistic_loss(-g_c)))
        balance = alpha_beta * (
            jnp.sum(weights_u * (logistic_loss(g_u) + logistic_loss(-g_u)))
            - jnp.sum(weights_c * (logistic_loss(g_c) + logistic_loss(-g_c)))
        )
        return supervised + balance

    return jnp.var(jax.vmap(one)(jax.random.split(key, num_resamples)))


def split_confidences(
    config: ClassifierConfig,
    spec: ClassifierSpec,
    classifier_coef,
    inputs,
    split,
    key,
    compiled: bool = True,
):
    """(float[M] the confidence every row of a split trains with, the labelled rows' mean):
    the given one on D_c's rows; on the rest the classifier's prediction (trained on the
    split's ``inputs`` float[M, O + A] by ``spec``), or D_c's mean for a method without a
    classifier (``classifier_coef`` 0). ``split`` is a ``demos.Split``.

    ``compiled`` False (static) leaves the classifier out of the program: right only where
    ``classifier_coef`` is 0, which then reads the same numbers as with it (the cond below
    takes, or under ``vmap`` selects, the branch without it)."""
    num_labelled = split.labelled.sum()
    mean_labelled = jnp.where(split.labelled, split.confidence, 0.0).sum() / jnp.maximum(
        num_labelled, 1
    )
    without_classifier = jnp.where(split.labelled, split.confidence, mean_labelled)

    def classify():
        predicted, _, _ = train_classifier(
            config, spec, inputs, split.confidence, split.labelled, key
        )
        return predicted

    if compiled:
        # Under vmap a cond with a batched predicate runs both branches; alone, only one.
        predicted = jax.lax.cond(classifier_coef > 0, classify, lambda: without_classifier)
    else:
        predicted = without_classifier
    confidence = jnp.where(
        split.labelled,
        split.confidence,
        classifier_coef * predicted + (1 - classifier_coef) * without_classifier,
    )
    return confidence, mean_labelled
