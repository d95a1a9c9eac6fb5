"""Methods as data: ``MethodSpec`` coefficients and the presets of the paper's comparison.

Every discriminator objective of ``docs/methods.md`` is one weighted sum of the same
per-sample terms (``pngail_jax.adversarial.losses.discriminator_loss``):

    L = A mean_agent sp(-z) + mean_demo [ u(x) sp(z) + v(x) sp(-z) ]

with ``A = agent_coef + icgail_coef Z`` and per-row weights ``u``, ``v`` built from the
confidence r, WGAIL's importance weight w and the D_c / D_u masks. A spec also says where r
comes from: ``classifier_coef`` 1 trains a confidence classifier (``bsc_coef`` 1 = BSC, 0 = SC)
for the unlabelled rows; 0 uses only the given labels (unlabelled rows get the mean labelled
confidence, which no preset reads). Specs are pytrees of floats, so a grid of methods is a
``vmap`` over stacked specs, never a Python branch.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax.confidence import ClassifierSpec
from pngail_jax.config.methods import (  # noqa: F401  (importable from here too)
    METHOD_DEFAULTS,
    check_preset,
    preset_record,
    register,
    register_recorded,
    required_phases,
    resolve,
)
from pngail_jax.config.presets import (  # noqa: F401  (the table, importable from here too)
    ALL_METHOD_NAMES,
    APPENDIX_METHOD_NAMES,
    APPENDIX_PRESETS,
    CONFIDENCE_SOURCES,
    DISPLAY_NAMES,
    METHOD_NAMES,
    PHASES,
    PRESETS,
    Preset,
    display_name,
    reads_confidences,
)


@struct.dataclass
class MethodSpec:
    """Loss coefficients and the confidence source of one method (all float[] leaves)."""

    agent_coef: jax.Array  # A += agent_coef: the agent term mean_agent sp(-z)
    gail_coef: jax.Array  # u += 1
    importance_weighted_coef: jax.Array  # u += r / mean(r)  (2IWIL, eq. 3)
    pn_coef: jax.Array  # u += r, v += 1 - r  (PN-GAIL, eq. 11)
    wgail_coef: jax.Array  # u += w = [exp(-z) pi(a|s)]^(1/2), refreshed on a schedule
    icgail_coef: (
        jax.Array
    )  # A += Z; u += 1[D_u] / P(D_u); v += (1-Z)/(1-mean r_c) 1[D_c]/P(D_c) (1-r)
    class_prior_floor: jax.Array  # IC-GAIL: Z = max(mean r_c, class_prior_floor)
    classifier_coef: jax.Array  # 1: unlabelled r from a trained classifier; 0: no classifier
    bsc_coef: jax.Array  # which classifier: 1 BSC (eq. 13), 0 SC (2IWIL)
    bsc_eps: jax.Array  # BSC's clip (0.01; the paper uses 0.05 on Walker2d)
    # The appendix baselines (pngail_jax.adversarial.ranking, .firl, .bc). Each reads its training
    # phase's output, and a phase runs only in grids with a method that needs it (PHASES).
    adversarial_reward_coef: jax.Array  # policy reward += coef sp(-z) (1 for the seven)
    policy_update_coef: jax.Array  # 1: TRPO updates the policy; 0: it stays as initialised
    bc_init_coef: jax.Array  # 1: the policy starts from behaviour cloning ("bc" phase)
    bc_weighted_coef: jax.Array  # BC row weights 1 + coef (r - 1): 1 = confidence-weighted
    ranking_reward_coef: jax.Array  # reward += coef r(s), learned from rankings (T-REX, D-REX)
    noise_rankings_coef: jax.Array  # 1: D-REX's reward (noisy rollouts), 0: T-REX's (confidence)
    firl_coef: jax.Array  # reward += coef r(s), f-IRL's reward ("firl" phase)
    firl_fkl_coef: jax.Array  # f-IRL's divergence: forward KL ...
    firl_rkl_coef: jax.Array  # ... reverse KL ...
    firl_js_coef: jax.Array  # ... Jensen-Shannon (pngail_jax.adversarial.firl.divergence_h)
    cail_coef: jax.Array  # 1: r is CAIL's learned per-trajectory confidence ("cail" phase)
    cail_learning_rate: jax.Array  # CAIL's gradient step on beta (0: beta frozen at 1)
    # Non-negative positive-unlabelled risks (losses.non_negative_pu_risk), the two ways round:
    # demonstrations labelled and the agent's rows unlabelled, a share pu_prior of them
    # expert-like (PU-GAIL): loss += pu_coef [eta mean_demo sp(z)
    #     + max(0, mean_agent sp(-z) - eta mean_demo sp(-z))], eta = pu_prior;
    # the agent's rows labelled and the demonstrations unlabelled, a share pu_agent_prior of
    # them agent-like (UID): loss += pu_agent_coef [pi mean_agent sp(-z)
    #     + max(0, mean_demo sp(z) - pi mean_agent sp(z))], pi = pu_agent_prior.
    pu_coef: jax.Array
    pu_prior: jax.Array  # in [0, 1)
    pu_agent_coef: jax.Array
    pu_agent_prior: jax.Array  # in [0, 1)
    # Remedies for a saturating PN discriminator (docs/results/remedies.md; none is a paper method):
    pn_negative_coef: jax.Array  # v's PN part times this (default 1; 0 drops the negative term)
    # 1: the PN risk's two classes weigh the same: the positive side (r sp(z)) divided by the
    # split's mean r, the negative side (the agent term and (1 - r) sp(-z)) by its own total
    # weight 1 + pn_negative_coef (1 - mean r); 0: as eq. 11.
    pn_balanced_coef: jax.Array
    # policy reward sp(-z) - logit_reward_coef sp(z): 0 is GAIL's -log D_agent, 1 the logit -z
    # (log D_demo - log D_agent, AIRL's form), which does not vanish when D saturates.
    logit_reward_coef: jax.Array
    # + coef mean ||grad_x z||^2 at points between agent and demonstration rows (a zero-centred
    # gradient penalty, which keeps the discriminator smooth where the two meet).
    gradient_penalty_coef: jax.Array

    @property
    def classifier(self) -> ClassifierSpec:
        return ClassifierSpec(bsc_coef=self.bsc_coef, eps=self.bsc_eps)


def method_spec(name: str, **overrides: float) -> MethodSpec:
    """The method ``name`` (a preset, a registered name or ``package.module:preset``;
    ``resolve``), with coefficients optionally overridden."""
    preset = resolve(name)
    unknown = set(overrides) - set(METHOD_DEFAULTS)
    if unknown:
        raise ValueError(
            f"unknown MethodSpec field(s) {sorted(unknown)}; known: {list(METHOD_DEFAULTS)}"
        )
    values = METHOD_DEFAULTS | preset.coefficients | overrides
    if not values["bsc_eps"] > 0:
        raise ValueError(f"bsc_eps must be positive, got {values['bsc_eps']!r}")
    return MethodSpec(**{k: jnp.asarray(v, jnp.float32) for k, v in values.items()})


def trains_classifier(methods, axes=()) -> bool:
    """Whether a grid of ``methods`` (names) and grid ``axes`` (``(field, values)`` pairs)
    has a cell that reads the confidence classifier (``classifier_coef`` nonzero: a preset's
    or a ``classifier_coef`` axis' value): the static choice of
    ``AdversarialConfig.confidence_classifier``."""
    by_method = any(
        (METHOD_DEFAULTS | resolve(name).coefficients)["classifier_coef"] for name in methods
    )
    by_axis = any(value for field, values in axes if field == "classifier_coef" for value in values)
    return bool(by_method or by_axis)


def stack(trees):
    """Stacks equal-structure pytrees (specs, hyperparameters) along a new leading axis."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)
