"""The methods' presets as plain data: each method's name, description, confidence source, loss
coefficients and training phases (``Preset``), the name tuples, and the paper's display
names. Imports nothing of the package and no JAX: the trainers
(``pngail_jax.adversarial.methods`` turns a preset into a ``MethodSpec`` and registers new
ones into ``PRESETS``) and the reading of run folders (``pngail_jax.analysis``, which imports
no JAX) read the same table."""

from __future__ import annotations

import dataclasses

# Training phases beyond the seven methods' (split, classifier, adversarial loop); a grid
# compiles only those its methods name (``required_phases``).
PHASES = ("bc", "demo_rankings", "noise_rankings", "firl", "cail")


# Where a method's confidences r come from: "none", "given" (D_c only), "sc", "bsc" (a
# classifier for D_u), or "rankings" (a label_ratio share of the trajectories, ranked by
# confidence).
CONFIDENCE_SOURCES = ("none", "given", "sc", "bsc", "rankings")


@dataclasses.dataclass(frozen=True)
class Preset:
    """A named method: its ``MethodSpec`` coefficients (the others take their defaults), where
    its confidences come from (``CONFIDENCE_SOURCES``) and the training phases it reads
    (``PHASES``). ``pngail_jax.adversarial.methods.register`` checks one against itself
    before a grid runs it."""

    description: str
    confidence_source: str
    coefficients: dict
    phases: tuple[str, ...] = ()


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

# The paper's seven: the default of every grid.
METHOD_NAMES = tuple(PRESETS)

_LEARNED_REWARD = {"adversarial_reward_coef": 0.0, "ranking_reward_coef": 1.0}
_FIRL = {"adversarial_reward_coef": 0.0, "firl_coef": 1.0}
APPENDIX_PRESETS: dict[str, Preset] = {
    "bc": Preset("BC: behaviour cloning on every demonstration, no RL", "none", {
        "policy_update_coef": 0.0, "bc_init_coef": 1.0}, ("bc",)),
    "bc-weighted": Preset("BC weighted by confidence (BSC on D_u), no RL", "bsc", {
        "policy_update_coef": 0.0, "bc_init_coef": 1.0, "bc_weighted_coef": 1.0, **_BSC},
        ("bc",)),
    "trex": Preset("T-REX: TRPO on a reward learned from trajectories ranked by confidence",
        "rankings", _LEARNED_REWARD, ("demo_rankings",)),
    "drex": Preset("D-REX: T-REX on rollouts of a cloned policy ranked by their noise",
        "none", {**_LEARNED_REWARD, "noise_rankings_coef": 1.0}, ("noise_rankings",)),
    "cail": Preset("CAIL: per-pair confidences learned by a bilevel ranking loss",
        "rankings", {"agent_coef": 1.0, "importance_weighted_coef": 1.0, "cail_coef": 1.0,
                     "cail_learning_rate": 0.1}, ("cail",)),
    "firl-fkl": Preset("f-IRL, forward KL: state reward from the divergence's gradient",
        "none", {**_FIRL, "firl_fkl_coef": 1.0}, ("firl",)),
    "firl-rkl": Preset("f-IRL, reverse KL", "none", {**_FIRL, "firl_rkl_coef": 1.0},
        ("firl",)),
    "firl-js": Preset("f-IRL, Jensen-Shannon", "none", {**_FIRL, "firl_js_coef": 1.0},
        ("firl",)),
}  # fmt: skip
APPENDIX_METHOD_NAMES = tuple(APPENDIX_PRESETS)
PRESETS.update(APPENDIX_PRESETS)
ALL_METHOD_NAMES = tuple(PRESETS)

# The paper's names, for legends and tables.
DISPLAY_NAMES = {
    "gail": "GAIL",
    "2iwil": "2IWIL",
    "icgail": "IC-GAIL",
    "wgail": "WGAIL",
    "pngail": "PN-GAIL",
    "pngail-no-bsc": "PN-GAIL\\BSC",
    "pngail-no-pn": "PN-GAIL\\PN",
    "bc": "BC",
    "bc-weighted": "BC, weighted",
    "trex": "T-REX",
    "drex": "D-REX",
    "cail": "CAIL",
    "firl-fkl": "f-IRL (FKL)",
    "firl-rkl": "f-IRL (RKL)",
    "firl-js": "f-IRL (JS)",
    # the offline family (pngail_jax.offline.trainer), which a report names the same way
    "bc-expert": "BC (expert rows)",
    "bc-all": "BC (all rows)",
    "dwbc": "DWBC",
    "iswbc": "ISW-BC",
    "ilid": "ILID",
}


def display_name(name: str) -> str:
    """The paper's name of a preset (``"pngail-no-bsc"``: ``"PN-GAIL\\BSC"``; an offline
    method's BSC variant ``"dwbc+bsc"``: ``"DWBC + BSC rows"``), else ``name``."""
    base, plus, rest = name.partition("+")
    if plus and rest == "bsc" and base in DISPLAY_NAMES:
        return f"{DISPLAY_NAMES[base]} + BSC rows"
    return DISPLAY_NAMES.get(name, name)


def reads_confidences(name: str) -> bool:
    """Whether a method's loss reads confidences (GAIL, WGAIL, BC, D-REX and f-IRL do not);
    True for a name that is not known."""
    return name not in PRESETS or PRESETS[name].confidence_source != "none"
