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

import dataclasses
import importlib

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax.confidence import ClassifierSpec
from pngail_jax.config import validation
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
    # Remedies for a saturating PN discriminator (docs/results.md; none is a paper method):
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


_DEFAULTS = {field.name: 0.0 for field in dataclasses.fields(MethodSpec)} | {
    "bsc_eps": 0.01,
    "adversarial_reward_coef": 1.0,
    "policy_update_coef": 1.0,
    "pn_negative_coef": 1.0,
}


# The coefficients that read confidences r, and the phase each learned part needs.
_READS_CONFIDENCE = (
    "importance_weighted_coef", "pn_coef", "icgail_coef", "bc_weighted_coef", "cail_coef",
)  # fmt: skip
_NEEDS_PHASE = {"bc_init_coef": ("bc",), "firl_coef": ("firl",), "cail_coef": ("cail",)}


def _float_coefficients(name: str, preset: Preset) -> dict[str, float]:
    """``preset``'s coefficients as floats; ValueError naming ``name`` for a preset that is
    not a ``Preset``, coefficients that are not a dict of known MethodSpec fields, or a value
    that is not a finite number."""
    if not isinstance(preset, Preset):
        raise ValueError(
            f"method {name!r}: a pngail_jax.adversarial.methods.Preset, got {type(preset)}"
        )
    if not isinstance(preset.coefficients, dict):
        raise ValueError(f"method {name!r}: coefficients must be a dict of MethodSpec fields")
    unknown = sorted(set(preset.coefficients) - set(_DEFAULTS), key=str)
    if unknown:
        raise ValueError(f"method {name!r}: unknown MethodSpec field(s) {unknown}")
    coefficients = {}
    for field, value in preset.coefficients.items():
        try:
            coefficients[field] = validation.real(field, value, "be a finite number")
        except validation.ConfigError as error:
            raise ValueError(f"method {name!r}: {error}") from None
    return coefficients


def check_preset(name: str, preset: Preset) -> Preset:
    """``preset`` with its coefficients as floats, if it is consistent; else ValueError naming
    ``name`` and the field: an unknown coefficient or phase, a confidence source that does not
    match its classifier coefficients or that a confidence-reading term lacks, a learned reward
    without the phase that learns it."""
    coefficients = _float_coefficients(name, preset)
    values = _DEFAULTS | coefficients
    source, phases = preset.confidence_source, tuple(preset.phases)

    def refuse(reason: str):
        raise ValueError(f"method {name!r}: {reason}")

    if source not in CONFIDENCE_SOURCES:
        refuse(f"confidence_source must be one of {CONFIDENCE_SOURCES}, got {source!r}")
    if not set(phases) <= set(PHASES):
        refuse(f"phases must be among {PHASES}, got {list(phases)}")
    for field in ("classifier_coef", "bsc_coef"):
        if values[field] not in (0.0, 1.0):
            refuse(f"{field} must be 0 or 1, got {values[field]}")
    if not 0 < values["bsc_eps"] < 0.5:
        refuse(f"bsc_eps must lie in (0, 0.5), got {values['bsc_eps']}")
    # The trainer reads these two only where a phase needs them (a learned reward replaces
    # the adversarial one; a cloned policy stays put): elsewhere a value other than 1 would
    # be silently ignored.
    if values["adversarial_reward_coef"] != 1.0 and not phases:
        refuse("adversarial_reward_coef other than 1 needs a phase whose reward replaces it")
    if values["policy_update_coef"] != 1.0 and "bc" not in phases:
        refuse("policy_update_coef other than 1 needs the 'bc' phase (a cloned policy)")
    _check_remedies(values, refuse)
    for coef, prior in (("pu_coef", "pu_prior"), ("pu_agent_coef", "pu_agent_prior")):
        if values[coef] and not 0 <= values[prior] < 1:
            refuse(f"{prior} must lie in [0, 1) with {coef}, got {values[prior]}")
    classifier = "bsc" if values["bsc_coef"] == 1.0 else "sc"
    if values["classifier_coef"] == 1.0 and source != classifier:
        refuse(f"classifier_coef 1 with bsc_coef {values['bsc_coef']} trains {classifier}: "
               f"confidence_source must be {classifier!r}, got {source!r}")  # fmt: skip
    if source in ("sc", "bsc") and values["classifier_coef"] != 1.0:
        refuse(f"confidence_source {source!r} needs classifier_coef 1 (a trained classifier)")
    readers = [field for field in _READS_CONFIDENCE if values[field] != 0.0]
    if readers and source == "none":
        refuse(f"{', '.join(readers)} read confidences: confidence_source cannot be 'none'")
    needed = {phase for field, need in _NEEDS_PHASE.items() if values[field] for phase in need}
    if values["ranking_reward_coef"]:
        needed.add("noise_rankings" if values["noise_rankings_coef"] else "demo_rankings")
    if not needed <= set(phases):
        refuse(f"its coefficients need the phase(s) {sorted(needed - set(phases))}: "
               "add them to phases")  # fmt: skip
    return dataclasses.replace(preset, coefficients=coefficients, phases=phases)


def _check_remedies(values: dict, refuse) -> None:
    """The remedies' ranges: weights >= 0, the class balance a blend in [0, 1]."""
    for field in ("pn_negative_coef", "logit_reward_coef", "gradient_penalty_coef"):
        if values[field] < 0:
            refuse(f"{field} must be >= 0, got {values[field]}")
    if not 0 <= values["pn_balanced_coef"] <= 1:
        refuse(f"pn_balanced_coef must lie in [0, 1], got {values['pn_balanced_coef']}")


def register(name: str, preset: Preset) -> Preset:
    """Adds a method a grid can run by ``name`` (``make_cells``, ``RunConfig(methods=...)``),
    checked by ``check_preset``. Registering the same preset again is a no-op; another one
    under a name in use is refused (the built-ins cannot be replaced)."""
    if not isinstance(name, str) or not name.strip() or "," in name:
        raise ValueError(f"a method name is a non-empty string without commas, got {name!r}")
    preset = check_preset(name, preset)
    if name in PRESETS and _record(PRESETS[name]) != _record(preset):
        raise ValueError(f"method {name!r} is already registered as another method")
    PRESETS[name] = preset
    return preset


def register_recorded(name: str, record: dict) -> Preset:
    """Registers ``name`` again from a saved run's ``preset_record``, so that a run of a method
    registered in another process resumes without that process's code."""
    return register(
        name,
        Preset(
            f"{name}, as a saved run recorded it",
            record["confidence_source"],
            dict(record["coefficients"]),
            tuple(record["phases"]),
        ),
    )


def resolve(name: str) -> Preset:
    """The preset of ``name``: a built-in or registered one, or ``"package.module:attribute"``
    naming a ``Preset`` (imported and registered under that name, so a saved run's config
    names it again). ValueError naming what is missing."""
    if not isinstance(name, str):
        raise ValueError(f"a method name is a string, got {name!r}")
    if name in PRESETS:
        return PRESETS[name]
    if ":" not in name:
        raise ValueError(
            f"unknown method {name!r}; available: {', '.join(PRESETS)}, a name given to "
            "pngail_jax.adversarial.methods.register, or package.module:preset"
        )
    module_name, _, attribute = name.partition(":")
    try:
        preset = getattr(importlib.import_module(module_name), attribute)
    except Exception as error:  # noqa: BLE001  the user's module: any error, in one line
        raise ValueError(
            f"method {name!r}: cannot import it ({type(error).__name__}: {error})"
        ) from None
    return register(name, preset)


def required_phases(methods) -> tuple[str, ...]:
    """The training phases (``PHASES``, in that order) that ``methods`` need."""
    needed = {phase for name in methods for phase in resolve(name).phases}
    return tuple(phase for phase in PHASES if phase in needed)


def method_spec(name: str, **overrides: float) -> MethodSpec:
    """The method ``name`` (a preset, a registered name or ``package.module:preset``;
    ``resolve``), with coefficients optionally overridden."""
    preset = resolve(name)
    unknown = set(overrides) - set(_DEFAULTS)
    if unknown:
        raise ValueError(f"unknown MethodSpec field(s) {sorted(unknown)}; known: {list(_DEFAULTS)}")
    values = _DEFAULTS | preset.coefficients | overrides
    if not values["bsc_eps"] > 0:
        raise ValueError(f"bsc_eps must be positive, got {values['bsc_eps']!r}")
    return MethodSpec(**{k: jnp.asarray(v, jnp.float32) for k, v in values.items()})


def stack(trees):
    """Stacks equal-structure pytrees (specs, hyperparameters) along a new leading axis."""
    return jax.tree.map(lambda *leaves: jnp.stack(leaves), *trees)


def preset_record(name: str) -> dict:
    """What ``name`` resolves to, as a saved run records it (``config.json``'s
    ``resolved.methods``), so a resume can tell whether it still runs the same method."""
    return _record(resolve(name))


def _record(preset: Preset) -> dict:
    return {
        "confidence_source": preset.confidence_source,
        "coefficients": dict(sorted(preset.coefficients.items())),
        "phases": list(preset.phases),
    }
