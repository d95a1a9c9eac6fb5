"""Methods as data: ``MethodSpec`` coefficients and the presets of the paper's comparison.

Every discriminator objective of ``docs/methods.md`` is one weighted sum of the same
per-sample terms (``pngail_jax.losses.discriminator_loss``):

    L = A mean_agent sp(-z) + mean_demo [ u(x) sp(z) + v(x) sp(-z) ]

with ``A = agent_coef + icgail_coef Z`` and per-row weights ``u``, ``v`` built from the
confidence r, WGAIL's importance weight w and the D_c / D_u masks. A spec also says where r
comes from: ``classifier_coef`` 1 trains a confidence classifier (``bsc_coef`` 1 = BSC, 0 = SC)
for the unlabelled rows; 0 uses only the given labels (unlabelled rows get the mean labelled
confidence, which no preset reads). Specs are pytrees of floats, so a grid of methods is a
``vmap`` over stacked specs, never a Python branch.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax.confidence import ClassifierSpec


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

    @property
    def classifier(self) -> ClassifierSpec:
        return ClassifierSpec(bsc_coef=self.bsc_coef, eps=self.bsc_eps)


@dataclasses.dataclass(frozen=True)
class Preset:
    description: str
    confidence_source: str  # "none", "given" (D_c only), "sc" or "bsc"
    coefficients: dict


_PN = {"agent_coef": 1.0, "pn_coef": 1.0}
_IW = {"agent_coef": 1.0, "importance_weighted_coef": 1.0}
_SC = {"classifier_coef": 1.0, "bsc_coef": 0.0}
_BSC = {"classifier_coef": 1.0, "bsc_coef": 1.0}

PRESETS: dict[str, Preset] = {
    "gail": Preset("GAIL: every demonstration is treated as optimal", "none", {
        "agent_coef": 1.0, "gail_coef": 1.0}),
    "2iwil": Preset("2IWIL: demonstrations weighted by r / mean(r), SC confidences", "sc", {
        **_IW, **_SC}),
    "icgail": Preset("IC-GAIL: D_c's given confidences only, Z = max(mean r_c, 0.7)", "given", {
        "icgail_coef": 1.0, "class_prior_floor": 0.7}),
    "wgail": Preset("WGAIL: weights [exp(-z) pi(a|s)]^(1/2), no confidences", "none", {
        "agent_coef": 1.0, "wgail_coef": 1.0}),
    "pngail": Preset("PN-GAIL: positive-negative risk (eq. 11), BSC confidences", "bsc", {
        **_PN, **_BSC}),
    "pngail-no-bsc": Preset("PN-GAIL\\BSC: PN-GAIL's loss with SC confidences", "sc", {
        **_PN, **_SC}),
    "pngail-no-pn": Preset("PN-GAIL\\PN: 2IWIL's loss with BSC confidences", "bsc", {
        **_IW, **_BSC}),
}  # fmt: skip

METHOD_NAMES = tuple(PRESETS)
_DEFAULTS = {field.name: 0.0 for field in dataclasses.fields(MethodSpec)} | {"bsc_eps": 0.01}


def method_spec(name: str, **overrides: float) -> MethodSpec:
    """The preset ``name`` (one of ``METHOD_NAMES``), with coefficients optionally overridden."""
    if name not in PRESETS:
        raise ValueError(f"unknown method {name!r}; available: {', '.join(METHOD_NAMES)}")
    unknown = set(overrides) - set(_DEFAULTS)
    if unknown:
        raise ValueError(f"unknown MethodSpec field(s) {sorted(unknown)}; known: {list(_DEFAULTS)}")
    values = _DEFAULTS | PRESETS[name].coefficients | overrides
    if not values["bsc_eps"] > 0:
        raise ValueError(f"bsc_eps must be positive, got {values['bsc_eps']!r}")
    return MethodSpec(**{k: jnp.asarray(v, jnp.float32) for k, v in values.items()})


def stack(trees):
    """Stacks equal-structure pytrees (specs, hyperparameters) along a new leading axis."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)
