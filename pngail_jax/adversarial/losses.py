"""The discriminator loss of every method, and the policy reward, as pure functions.

Notation of ``docs/methods.md``: z is the discriminator logit, agent rows have label 1
(sigmoid(z) -> 1), demonstrations label 0, ``sp`` is softplus, ``sp(-z) = -log sigmoid(z)``.
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax.adversarial.methods import MethodSpec

_TINY = 1e-8


def policy_reward(logits: jax.Array, logit_coef: jax.Array | float = 0.0) -> jax.Array:
    """-log sigmoid(z) = sp(-z): large where the discriminator thinks a pair is a demo's.

    With ``logit_coef`` c, ``sp(-z) - c sp(z)`` = -log D_agent + c log D_demo: c = 1 gives
    the logit -z (AIRL's log D - log(1 - D)), which keeps telling pairs apart when the
    discriminator saturates and sp(-z) -> 0 on every agent pair."""
    reward = jax.nn.softplus(-logits)
    # where, not a product: a method without the term keeps every bit of its reward
    return jnp.where(logit_coef != 0, reward - logit_coef * jax.nn.softplus(logits), reward)


@struct.dataclass
class ConfidenceStats:
    """Split-wide statistics the losses need (float[] each)."""

    mean_confidence: jax.Array  # mean r over all demonstrations of the split (2IWIL)
    mean_labelled_confidence: jax.Array  # mean r over D_c (IC-GAIL's mean r_c)


def demo_weights(
    spec: MethodSpec,
    confidence: jax.Array,
    labelled: jax.Array,
    importance_weight: jax.Array,
    stats: ConfidenceStats,
):
    """Per-method coefficients of the shared terms for a batch of B demonstration rows.

    Args: confidence float[B] (r), labelled bool[B] (row in D_c), importance_weight float[B]
    (WGAIL's w). Returns ``(agent_coef float[], u float[B], v float[B])`` such that the loss is
    ``agent_coef mean_agent sp(-z) + mean_B [u sp(z) + v sp(-z)]``. IC-GAIL's means over D_c
    and D_u are means over the batch's rows of each set (weights 1[D] / P_batch(D)).
    """
    labelled = labelled.astype(confidence.dtype)
    fraction_labelled = labelled.mean()
    labelled_share = labelled / jnp.maximum(fraction_labelled, _TINY)
    unlabelled_share = (1 - labelled) / jnp.maximum(1 - fraction_labelled, _TINY)
    mean_rc = stats.mean_labelled_confidence
    class_prior = jnp.maximum(mean_rc, spec.class_prior_floor)
    # Z >= mean r_c, so this lies in [0, 1]; 0 when every labelled row is certain (r_c = 1).
    labelled_negative_coef = jnp.where(
        mean_rc < 1, (1 - class_prior) / jnp.maximum(1 - mean_rc, _TINY), 0.0
    )
    positive_scale, negative_scale = _pn_balance(spec, stats.mean_confidence)
    u = (
        spec.gail_coef
        + spec.importance_weighted_coef * confidence / jnp.maximum(stats.mean_confidence, _TINY)
        + spec.pn_coef * positive_scale * confidence
        # where, not a product: 0 * inf (an overflowing w) would be NaN in other methods
        + jnp.where(spec.wgail_coef != 0, spec.wgail_coef * importance_weight, 0.0)
        + spec.icgail_coef * unlabelled_share
    )
    v = spec.pn_coef * spec.pn_negative_coef * negative_scale * (
        1 - confidence
    ) + spec.icgail_coef * labelled_negative_coef * (labelled_share * (1 - confidence))
    agent_coef = spec.agent_coef * negative_scale + spec.icgail_coef * class_prior
    return agent_coef, u, v


def _pn_balance(spec: MethodSpec, mean_confidence: jax.Array):
    """The factors of the PN risk's positive side (r sp(z)) and negative side (the agent term
    and (1 - r) sp(-z)) that ``pn_balanced_coef`` b blends in: 1 at b = 0 (eq. 11 as it is);
    at b = 1, 1 / mean r and 1 / (1 + pn_negative_coef (1 - mean r)), so that each side's
    total weight over the split is 1. Both are exactly 1.0 where b = 0, so the other methods'
    losses keep every bit."""
    balanced = spec.pn_balanced_coef
    negative_total = 1 + spec.pn_negative_coef * (1 - mean_confidence)
    positive = 1 - balanced + balanced / jnp.maximum(mean_confidence, _TINY)
    negative = 1 - balanced + balanced / negative_total
    return positive, negative


def non_negative_pu_risk(prior, labelled_own, labelled_other, unlabelled_other):
    """Kiryo et al. (2017)'s non-negative PU risk: ``prior labelled_own + max(0,
    unlabelled_other - prior labelled_other)``, from the mean losses of the labelled rows as
    their own class (``labelled_own``) and as the other class (``labelled_other``), and of the
    unlabelled rows as the other class; ``prior`` is the share of the labelled class among the
    unlabelled rows. The max keeps the other class's estimated risk from going below 0, where
    a flexible discriminator would overfit."""
    return prior * labelled_own + jnp.maximum(unlabelled_other - prior * labelled_other, 0.0)


def _pu_terms(spec: MethodSpec, agent_term, logits_agent, logits_demo):
    """PU-GAIL's risk (demonstrations labelled as the expert class, sp(z); the agent's rows
    unlabelled) and UID's (the agent's rows labelled as the agent class, sp(-z); the
    demonstrations unlabelled), each times its coefficient."""
    demo_expert = jnp.mean(jax.nn.softplus(logits_demo))
    demo_agent = jnp.mean(jax.nn.softplus(-logits_demo))
    agent_expert = jnp.mean(jax.nn.softplus(logits_agent))
    pu_gail = non_negative_pu_risk(spec.pu_prior, demo_expert, demo_agent, agent_term)
    uid = non_negative_pu_risk(spec.pu_agent_prior, agent_term, agent_expert, demo_expert)
    return spec.pu_coef * pu_gail + spec.pu_agent_coef * uid


def discriminator_loss(
    spec: MethodSpec,
    logits_agent: jax.Array,
    logits_demo: jax.Array,
    confidence: jax.Array,
    labelled: jax.Array,
    importance_weight: jax.Array,
    stats: ConfidenceStats,
):
    """The method's discriminator objective (minimised) on one batch.

    Args: logits_agent float[N] on agent pairs (actions clipped to the bounds), logits_demo
    float[B] on demonstration rows with their confidence float[B], labelled bool[B] and
    importance_weight float[B]. Returns ``(loss, metrics)``.
    """
    chex.assert_rank(logits_agent, 1)
    chex.assert_equal_shape([logits_demo, confidence, labelled, importance_weight])
    agent_coef, u, v = demo_weights(spec, confidence, labelled, importance_weight, stats)
    agent_term = jnp.mean(jax.nn.softplus(-logits_agent))
    demo_term = jnp.mean(u * jax.nn.softplus(logits_demo) + v * jax.nn.softplus(-logits_demo))
    loss = agent_coef * agent_term + demo_term
    # where, not a product: the other methods' loss stays the same float to the last bit
    uses_pu = (spec.pu_coef != 0) | (spec.pu_agent_coef != 0)
    loss = loss + jnp.where(uses_pu, _pu_terms(spec, agent_term, logits_agent, logits_demo), 0.0)
    return loss, {
        "disc/loss": loss,
        "disc/acc_agent": jnp.mean(logits_agent > 0),
        "disc/acc_demo": jnp.mean(logits_demo < 0),
    }
