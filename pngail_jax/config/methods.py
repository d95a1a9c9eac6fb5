"""The method part of a run's config, as plain data and plain checks: ``MethodSpec``'s default
coefficients (``METHOD_DEFAULTS``), the check of a preset against itself (``check_preset``),
the registry of methods by name (``register``, ``register_recorded``, ``resolve``, which
imports a ``"package.module:preset"``), the phases a grid's methods need and what a saved run
records of a method (``preset_record``). Imports no JAX: ``RunConfig`` checks its methods
here, and ``pngail_jax.adversarial.methods`` turns a preset into a ``MethodSpec`` (and
re-exports these names)."""

from __future__ import annotations

import dataclasses
import importlib

from pngail_jax.config import validation
from pngail_jax.config.classifier import DEFAULT_BSC_EPS
from pngail_jax.config.grid_axes import METHOD_AXES
from pngail_jax.config.presets import CONFIDENCE_SOURCES, PHASES, PRESETS, Preset

# MethodSpec's values where a preset leaves a coefficient out.
METHOD_DEFAULTS = {name: 0.0 for name in METHOD_AXES} | {
    "bsc_eps": DEFAULT_BSC_EPS,
    "adversarial_reward_coef": 1.0,
    "policy_update_coef": 1.0,
    "pn_negative_coef": 1.0,
}


# The coefficients that read confidences r, and the phase each learned part needs.
_READS_CONFIDENCE = (
    "importance_weighted_coef", "pn_coef", "icgail_coef", "bc_weighted_coef", "cail_coef",
)  # fmt: skip
_NEEDS_PHASE = {"bc_init_coef": ("bc",), "firl_coef": ("firl",), "cail_coef": ("cail",)}


def check_preset(name: str, preset: Preset) -> Preset:
    """``preset`` with its coefficients as floats, if it is consistent; else ValueError naming
    ``name`` and the field: an unknown coefficient or phase, a confidence source that does not
    match its classifier coefficients or that a confidence-reading term lacks, a learned reward
    without the phase that learns it."""
    if not isinstance(preset, Preset):
        raise ValueError(
            f"method {name!r}: a pngail_jax.adversarial.methods.Preset, got {type(preset)}"
        )
    if not isinstance(preset.coefficients, dict):
        raise ValueError(f"method {name!r}: coefficients must be a dict of MethodSpec fields")
    unknown = sorted(set(preset.coefficients) - set(METHOD_DEFAULTS), key=str)
    if unknown:
        raise ValueError(f"method {name!r}: unknown MethodSpec field(s) {unknown}")
    coefficients = {}
    for field, value in preset.coefficients.items():
        try:
            coefficients[field] = validation.real(field, value, "be a finite number")
        except validation.ConfigError as error:
            raise ValueError(f"method {name!r}: {error}") from None
    values = METHOD_DEFAULTS | coefficients
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
    _check_confidence_source(values, source, refuse)
    needed = {phase for field, need in _NEEDS_PHASE.items() if values[field] for phase in need}
    if values["ranking_reward_coef"]:
        needed.add("noise_rankings" if values["noise_rankings_coef"] else "demo_rankings")
    if not needed <= set(phases):
        refuse(f"its coefficients need the phase(s) {sorted(needed - set(phases))}: "
               "add them to phases")  # fmt: skip
    return dataclasses.replace(preset, coefficients=coefficients, phases=phases)


def _check_confidence_source(values: dict, source: str, refuse) -> None:
    """The confidence source against the coefficients: the classifier they train, and a
    source for every term that reads confidences."""
    classifier = "bsc" if values["bsc_coef"] == 1.0 else "sc"
    if values["classifier_coef"] == 1.0 and source != classifier:
        refuse(f"classifier_coef 1 with bsc_coef {values['bsc_coef']} trains {classifier}: "
               f"confidence_source must be {classifier!r}, got {source!r}")  # fmt: skip
    if source in ("sc", "bsc") and values["classifier_coef"] != 1.0:
        refuse(f"confidence_source {source!r} needs classifier_coef 1 (a trained classifier)")
    readers = [field for field in _READS_CONFIDENCE if values[field] != 0.0]
    if readers and source == "none":
        refuse(f"{', '.join(readers)} read confidences: confidence_source cannot be 'none'")


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
