"""The offline methods' losses, pure (docs/methods.md, "Offline methods").

Notation: E an expert batch, O a batch of the other (not expert) rows, U a batch of every row
(the union, expert rows included); nll = -log pi(a | s) of the policy, per row. Each loss
returns ``(loss, metrics)`` and states its shapes; none reads a network, so each is tested
against a NumPy computation of its formula (tests/test_offline_losses.py).
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp

# ISW-BC's offsets inside its weight and its penalty's norm (the ISWBC codebase: 1e-3 in
# g(x) = log(1 / (sigmoid(c) + 1e-3) - 1 + 1e-3); float32's machine epsilon added to the
# gradient before its norm).
ISWBC_WEIGHT_OFFSET = 1e-3
ISWBC_NORM_OFFSET = 1.1920929e-07


def log_density_feature(log_density: jax.Array) -> jax.Array:
    """DWBC's discriminator input from the policy's per-dimension log-density float[B, A]:
    clipped to [-20, 10], mapped to [0, 1] by (l + 20) / 30, no gradient to the policy."""
    return jax.lax.stop_gradient((jnp.clip(log_density, -20.0, 10.0) + 20.0) / 30.0)


def dwbc_discriminator_loss(d_expert: jax.Array, d_other: jax.Array, eta: jax.Array):
    """DWBC's positive-unlabelled loss on d float[B] (in (0, 1), expert = 1) of an expert and
    an other batch of one size:

        mean_i [ -log d_E,i - log(1 - d_O,i) / eta + log(1 - d_E,i) ]

    (the paper's eta E_E[-log d] + E_O[-log(1 - d)] - eta E_E[-log(1 - d)], divided by eta).
    """
    chex.assert_equal_shape([d_expert, d_other])
    loss = jnp.mean(-jnp.log(d_expert) - jnp.log1p(-d_other) / eta + jnp.log1p(-d_expert))
    return loss, {"dwbc/disc_loss": loss}


def dwbc_weights(d_expert: jax.Array, d_other: jax.Array, eta: jax.Array):
    """DWBC's weights of its policy loss from d float[...] (held fixed): (w_E, w_O),
    w_E = eta / (d_E (1 - d_E)) + 1 (an expert row's nll gets alpha - w_E in all) and
    w_O = d_O / (1 - d_O) where d_O >= 0.5, else 0 (the codebase's 1 / (1 - d) - 1 with d
    below 0.5 set to 0)."""
    kept = jnp.where(d_other >= 0.5, d_other, 0.0)
    return eta / (d_expert * (1 - d_expert)) + 1, kept / (1 - kept)


def dwbc_evaluation_metrics(
    d: jax.Array,
    expert_probability: jax.Array,
    other_probability: jax.Array,
    alpha: jax.Array,
    eta: jax.Array,
) -> dict[str, jax.Array]:
    """What DWBC's discriminator says of the whole split at an evaluation: d float[M] on
    every row, read under the probabilities float[M] its expert and other batches are drawn
    with (uniform over E, over O): the mean d on E (``dwbc/eval_d_expert``) and on O
    (``dwbc/eval_d_other``), the mean net weight alpha - w_E of an expert row's nll
    (``dwbc/eval_weight_expert``) and the mean weight w_O of an other row's
    (``dwbc/eval_weight_other``, ``dwbc_weights``). float[] each."""
    chex.assert_equal_shape([d, expert_probability, other_probability])
    weight_expert, weight_other = dwbc_weights(d, d, eta)
    return {
        "dwbc/eval_d_expert": jnp.sum(expert_probability * d),
        "dwbc/eval_d_other": jnp.sum(other_probability * d),
        "dwbc/eval_weight_expert": jnp.sum(expert_probability * (alpha - weight_expert)),
        "dwbc/eval_weight_other": jnp.sum(other_probability * weight_other),
    }


def dwbc_policy_loss(
    nll_expert: jax.Array,
    nll_other: jax.Array,
    d_expert: jax.Array,
    d_other: jax.Array,
    alpha: jax.Array,
    eta: jax.Array,
):
    """DWBC's weighted behaviour cloning, nll and d float[B] per batch (d held fixed):

        alpha mean_E[nll] - mean_E[w_E nll] + mean_O[w_O nll],
        w_E = eta / (d (1 - d)) + 1,  w_O = d / (1 - d) where d >= 0.5, else 0.

    With d in [0.1, 0.9] an expert row's net weight alpha - w_E lies in [alpha - 6.56,
    alpha - 3]: positive at the codebase's alpha 7.5."""
    chex.assert_equal_shape([nll_expert, nll_other, d_expert, d_other])
    d_expert, d_other = jax.lax.stop_gradient((d_expert, d_other))
    weight_expert, weight_other = dwbc_weights(d_expert, d_other, eta)
    loss = (
        alpha * jnp.mean(nll_expert)
        - jnp.mean(weight_expert * nll_expert)
        + jnp.mean(weight_other * nll_other)
    )
    return loss, {
        "dwbc/policy_loss": loss,
        "dwbc/kept_other": jnp.mean(d_other >= 0.5),
        "dwbc/mean_d_expert": jnp.mean(d_expert),
        "dwbc/mean_d_other": jnp.mean(d_other),
    }


def iswbc_discriminator_loss(logits_expert: jax.Array, logits_union: jax.Array):
    """Logistic regression of the expert batch (label 1) against the union batch (label 0),
    logits c float[B] each: mean_E[-log sigmoid(c)] + mean_U[-log(1 - sigmoid(c))]."""
    loss = jnp.mean(jax.nn.softplus(-logits_expert)) + jnp.mean(jax.nn.softplus(logits_union))
    return loss, {"iswbc/disc_loss": loss}


def iswbc_log_odds(logits: jax.Array) -> jax.Array:
    """ISW-BC's g(x) = log(1 / (sigmoid(c) + 1e-3) - 1 + 1e-3), about -c: float[...]."""
    return jnp.log(1 / (jax.nn.sigmoid(logits) + ISWBC_WEIGHT_OFFSET) - 1 + ISWBC_WEIGHT_OFFSET)


def iswbc_weights(logits: jax.Array) -> jax.Array:
    """ISW-BC's importance weight exp(-g(x)), about D / (1 - D) (the density ratio of the
    expert to the union, when D is the optimal discriminator), bounded in about [1e-3, 1e6];
    no gradient flows. float[...]."""
    return jax.lax.stop_gradient(jnp.exp(-iswbc_log_odds(logits)))


def one_centred_penalty(gradients: jax.Array) -> jax.Array:
    """mean_i (||g_i + eps||_2 - 1)^2 over gradients float[P, D] (ISW-BC's penalty on the
    gradient of g at points between its batches; eps added to every element): float[]."""
    norms = jnp.sqrt(jnp.sum(jnp.square(gradients + ISWBC_NORM_OFFSET), axis=-1))
    return jnp.mean(jnp.square(norms - 1))


def weighted_nll(nll: jax.Array, weights: jax.Array, cutoff: jax.Array = 0.0):
    """mean_i 1[w_i >= cutoff] w_i nll_i, nll and w float[B] (w held fixed): ISW-BC's
    weighted behaviour cloning on the union batch."""
    chex.assert_equal_shape([nll, weights])
    weights = jax.lax.stop_gradient(jnp.where(weights >= cutoff, weights, 0.0))
    loss = jnp.mean(weights * nll)
    return loss, {"iswbc/policy_loss": loss, "iswbc/mean_weight": jnp.mean(weights)}


# -- ILID (Yue et al., 2024): select behaviours by the states they lead to -----------------------

# ILID's discriminators output sigmoid(logit) clipped to [0.1, 0.9] (as DWBC's, "for a fair
# comparison" in its codebase).
ILID_CLIP = (0.1, 0.9)


def clipped_probability(logits: jax.Array) -> jax.Array:
    """ILID's discriminator output: sigmoid(logit) clipped to [0.1, 0.9], float[...]."""
    return jnp.clip(jax.nn.sigmoid(logits), *ILID_CLIP)


def ilid_discriminator_loss(d_positive: jax.Array, d_negative: jax.Array):
    """The logistic loss of both ILID discriminators, d float[B] each (positive = 1):
    mean_i [-log d_P,i - log(1 - d_N,i)]. The state discriminator's positives are the expert
    rows' states and its negatives the other rows'; the state-action one's, the expert rows
    against the union of the expert and the selected rows."""
    chex.assert_equal_shape([d_positive, d_negative])
    loss = jnp.mean(-jnp.log(d_positive) - jnp.log1p(-d_negative))
    return loss, {"ilid/disc_loss": loss}


def ilid_selection(expert_like: jax.Array, successors: jax.Array) -> jax.Array:
    """bool[M]: ILID's selected behaviours. ``expert_like`` bool[N] says which rows' states
    the state discriminator puts at or above the bar; ``successors`` int[M, K] holds, per
    candidate row, the rows of the K states after it in its trajectory (k = 1..K, -1 past
    the trajectory's end). A row is selected when any of those K states is expert-like: its
    action leads, within K steps, to where the expert goes (the codebase's "rollback")."""
    present = successors >= 0
    reached = jnp.where(present, expert_like[jnp.maximum(successors, 0)], False)
    return reached.any(axis=-1)
