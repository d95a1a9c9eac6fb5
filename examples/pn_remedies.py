"""Remedies for PN-GAIL's saturating discriminator, as presets (none is a paper method).

    python -m experiments.sweep --demos data/released/HalfCheetah-v2_mixture.npy \
        --methods pngail,2iwil,gail,examples.pn_remedies:negative_half,\
examples.pn_remedies:balanced,examples.pn_remedies:logit_reward,\
examples.pn_remedies:gradient_penalty

On the authors' HalfCheetah file PN-GAIL's discriminator calls the agent and the ~70% of
demonstrations with confidence near 0 one class, separates the agent from everything else,
and its reward sp(-z) vanishes (docs/results/tenth-budget.md). Each preset below is PN-GAIL
(eq. 11, BSC confidences) with one change, through a ``MethodSpec`` coefficient:

- ``negative_half``: the negative term (1 - r) sp(-z) at half weight (``pn_negative_coef``
  0.5; 0 is 2IWIL's loss without its r / mean r, 1 is PN-GAIL: a dial, ``--grid
  pn_negative_coef=0,0.25,0.5,1`` sweeps it);
- ``balanced``: the two classes of the PN risk weigh the same (``pn_balanced_coef`` 1): the
  positive side r sp(z) scaled by 1 / mean r, the negative side (agent term and
  (1 - r) sp(-z)) by 1 / (1 + mean(1 - r)), so 30% of optimal rows are not outweighed by
  1.7 units of agent-like rows;
- ``logit_reward``: the policy's reward is the logit -z = sp(-z) - sp(z) (AIRL's
  log D - log(1 - D)), which keeps ordering the agent's pairs when D saturates
  (``logit_reward_coef`` 1);
- ``gradient_penalty``: a zero-centred gradient penalty 10 mean ||grad_x z||^2 at points
  between agent and demonstration rows (``gradient_penalty_coef`` 10, the weight of
  Kostrikov et al.'s DAC), which keeps the discriminator from a sharp boundary.

One control, not a remedy: ``iwil_gradient_penalty`` is 2IWIL with the same penalty, so a
grid with both says whether the penalty mends PN-GAIL's risk or is a better discriminator
for every method.
"""

from pngail_jax.adversarial.methods import PRESETS, Preset

_PNGAIL = PRESETS["pngail"].coefficients
_IWIL = PRESETS["2iwil"]

negative_half = Preset(
    "PN-GAIL with its negative term at half weight", "bsc", {**_PNGAIL, "pn_negative_coef": 0.5}
)
balanced = Preset("PN-GAIL with class-balanced terms", "bsc", {**_PNGAIL, "pn_balanced_coef": 1.0})
logit_reward = Preset(
    "PN-GAIL with the logit reward -z", "bsc", {**_PNGAIL, "logit_reward_coef": 1.0}
)
gradient_penalty = Preset(
    "PN-GAIL with a gradient penalty (10)", "bsc", {**_PNGAIL, "gradient_penalty_coef": 10.0}
)
iwil_gradient_penalty = Preset(
    "2IWIL with a gradient penalty (10)",
    _IWIL.confidence_source,
    {**_IWIL.coefficients, "gradient_penalty_coef": 10.0},
)
