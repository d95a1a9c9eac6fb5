"""The learner part of a run's config, as plain data: the policy learners' names, TRPO's
Fisher forms and their default, the checks of a config's learner fields, written once for
every job's config (the sweep's ``RunConfig``, ``TrainRLConfig``, ``MakeDemosConfig``), and
the learners' static settings: ``RolloutConfig`` (what both share), ``TRPOConfig``,
``PPOConfig`` and ``check_batch``. Imports no JAX: ``pngail_jax.rl`` builds the learners
these describe and re-exports the names (``rl.on_policy``, ``rl.trpo``, ``rl.ppo``,
``rl.learners``)."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from typing import Literal

from pngail_jax.config.validation import ConfigError, fail, is_among

# "trpo" (the paper's, the default) and "ppo" (pngail_jax.rl.learners builds them).
LEARNERS = ("trpo", "ppo")
DEFAULT_LEARNER = "trpo"
# TRPO's Fisher-vector product: "gauss_newton" (J^T M J v, one jvp and one vjp, the default
# everywhere: library, sweep, train_rl) or "hessian" (the reference's second-order form).
FISHER_FORMS = ("gauss_newton", "hessian")
DEFAULT_FISHER = "gauss_newton"
# GAE as a T-step scan or a log-depth tree (pngail_jax.rl.gae).
GAEForm = Literal["sequential", "associative"]


# The per-cell values each learner reads: the fields of rl.trpo.TRPOHyperparams and
# rl.ppo.PPOHyperparams, in order (tests/test_grid_axes.py holds them to the classes).
HYPERPARAM_NAMES = {
    "trpo": ("gamma", "lam", "max_kl", "damping", "value_learning_rate", "bootstrap_truncation"),
    "ppo": (
        "gamma", "lam", "clip_eps", "learning_rate", "entropy_coef", "value_coef",
        "max_grad_norm", "bootstrap_truncation",
    ),
}  # fmt: skip
HYPERPARAM_CLASSES = {"trpo": "TRPOHyperparams", "ppo": "PPOHyperparams"}


def learner_name(name) -> str:
    """``name`` when it is a learner's, else ConfigError (a ValueError) naming the choices."""
    if not is_among(name, LEARNERS):
        raise ConfigError("learner", f"must be one of {', '.join(LEARNERS)}, got {name!r}")
    return name


def hyperparam_names(name: str) -> tuple[str, ...]:
    """The per-cell values learner ``name`` reads (its hyperparameters' fields)."""
    return HYPERPARAM_NAMES[learner_name(name)]


def check_hyperparam_names(name: str, values) -> None:
    """ValueError naming each of ``values`` that learner ``name`` does not read, and which
    learner does."""
    known = hyperparam_names(name)
    foreign = [field for field in values if field not in known]
    if foreign:
        others = {
            field: [other for other in LEARNERS if field in hyperparam_names(other)]
            for field in foreign
        }
        described = ", ".join(
            f"{field} ({'/'.join(owners)}'s)" if owners else field
            for field, owners in others.items()
        )
        raise ValueError(
            f"the {name} learner has no hyperparameter {described}; its own: {', '.join(known)}"
        )


def check_hyperparam(name: str, field: str, value) -> None:
    """One of learner ``name``'s float hyperparameters in its range: positive (gamma and lam
    at most 1), PPO's entropy coefficient >= 0. ValueError naming it."""
    where = f"{HYPERPARAM_CLASSES[name]}.{field}"
    if field == "entropy_coef":
        if not value >= 0:
            raise ValueError(f"{where} must be >= 0, got {value!r}")
    elif not (value > 0) or (field in ("gamma", "lam") and value > 1):
        raise ValueError(f"{where} out of range: {value!r}")


def check_discriminator_learning_rate(value) -> None:
    """The discriminator's per-cell step size: positive (ValueError otherwise)."""
    if not value > 0:
        raise ValueError(f"discriminator_learning_rate must be positive, got {value!r}")


def check_cell_value(learner: str, field: str, value) -> None:
    """A grid axis's value of a per-cell hyperparameter (not a MethodSpec coefficient) under
    ``learner``: the discriminator's step size or one the learner reads, in its range."""
    if field == "discriminator_learning_rate":
        check_discriminator_learning_rate(value)
    else:
        check_hyperparam_names(learner, [field])
        check_hyperparam(learner, field, value)


@dataclasses.dataclass(frozen=True)
class RolloutConfig:
    """What both learners share, static: the rollout's shape (``num_envs * unroll_length``
    steps per iteration), the run's length, the evaluation, the networks and the observation
    normaliser. Each learner's own settings are its config beside it (``rl.trpo.TRPOConfig``,
    ``rl.ppo.PPOConfig``)."""

    num_envs: int = 25
    unroll_length: int = 200
    num_iterations: int = 100
    eval_every: int = 10
    num_eval_episodes: int = 32
    hidden_sizes: tuple[int, ...] = (100, 100)
    normalize_observations: bool = False
    # GAE as a T-step scan ("sequential") or a log-depth tree ("associative"): the same
    # numbers up to float rounding (tests/test_gae.py); which is faster depends on the device.
    gae_form: GAEForm = "sequential"
    # Each env's first episode truncated at a random length (envs.AutoReset.staggered_reset),
    # so that the envs of a task that never terminates do not stay in step.
    stagger_starts: bool = False

    def __post_init__(self):
        for name in (
            "num_envs", "unroll_length", "num_iterations", "eval_every", "num_eval_episodes",
        ):  # fmt: skip
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"RolloutConfig.{name} must be a positive integer, got {value!r}")
        if self.num_iterations % self.eval_every:
            raise ValueError(
                f"RolloutConfig.num_iterations ({self.num_iterations}) must be a "
                f"multiple of eval_every ({self.eval_every})"
            )
        if not isinstance(self.stagger_starts, bool):
            raise ValueError(
                f"RolloutConfig.stagger_starts must be True or False, got {self.stagger_starts!r}"
            )
        if self.gae_form not in ("sequential", "associative"):
            raise ValueError(
                "RolloutConfig.gae_form must be 'sequential' or 'associative', "
                f"got {self.gae_form!r}"
            )

    @property
    def batch_size(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def num_evaluations(self) -> int:
        return self.num_iterations // self.eval_every


@dataclasses.dataclass(frozen=True)
class TRPOConfig:
    """TRPO's own static settings (loop counts and which Fisher product is compiled); the
    rollout's shape and the networks are ``RolloutConfig``'s, which both learners share."""

    num_value_minibatches: int = 30
    # Passes of the value fit over the batch, each a fresh permutation (the reference: 1);
    # the logged value/loss is the mean over every pass's minibatches.
    num_value_epochs: int = 1
    num_cg_iterations: int = 10
    num_backtracks: int = 10
    # "hessian": Hessian of the mean KL times v, the reference's form (second-order autodiff).
    # "gauss_newton": J^T M J v for the Gaussian policy, the same matrix at the current
    # parameters, from one jvp and one vjp, and faster: the default everywhere (library,
    # sweep, train_rl), so that Python and the command line run the same program.
    fisher: Literal["hessian", "gauss_newton"] = DEFAULT_FISHER
    # Fisher products on every k-th time step of every env (OpenAI baselines uses every 5th
    # sample); 1 = all.
    fisher_subsample: int = 1

    def __post_init__(self):
        for name in (
            "num_value_minibatches",
            "num_value_epochs",
            "num_cg_iterations",
            "num_backtracks",
            "fisher_subsample",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                fail(name, f"must be a positive integer, got {value!r}", name=f"TRPOConfig.{name}")
        if not is_among(self.fisher, FISHER_FORMS):
            fail("fisher", f"must be one of {FISHER_FORMS}, got {self.fisher!r}",
                 name="TRPOConfig.fisher")  # fmt: skip

    def check_batch(self, rollout: RolloutConfig) -> None:
        """Raises ValueError when the rollout has fewer samples than value minibatches."""
        if rollout.batch_size < self.num_value_minibatches:
            raise ValueError(
                f"samples per iteration (num_envs x unroll_length = {rollout.num_envs} x "
                f"{rollout.unroll_length} = {rollout.batch_size}) must be at least the "
                f"{self.num_value_minibatches} value minibatches"
            )


@dataclasses.dataclass(frozen=True)
class PPOConfig:
    """PPO's static settings (loop counts and which losses are compiled); the rollout's shape
    and the networks are ``RolloutConfig``'s, which both learners share."""

    num_epochs: int = 10
    num_minibatches: int = 32
    clip_value_loss: bool = True
    anneal_learning_rate: bool = True
    # Rewards divided by the running standard deviation of each env's discounted return and
    # clipped to [-10, 10] (CleanRL's NormalizeReward wrapper), before GAE.
    normalize_rewards: bool = True

    def __post_init__(self):
        for name in ("num_epochs", "num_minibatches"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                fail(name, f"must be a positive integer, got {value!r}", name=f"PPOConfig.{name}")
        for name in ("clip_value_loss", "anneal_learning_rate", "normalize_rewards"):
            if not isinstance(getattr(self, name), bool):
                fail(name, "must be True or False", name=f"PPOConfig.{name}")

    def check_batch(self, config: RolloutConfig) -> None:
        """Raises ValueError when the rollout has fewer samples than minibatches."""
        if config.batch_size < self.num_minibatches:
            raise ValueError(
                f"samples per iteration (num_envs x unroll_length = {config.batch_size}) must "
                f"be at least PPO's {self.num_minibatches} minibatches"
            )


def check_batch(
    name: str, config: RolloutConfig, ppo: PPOConfig | None = None, trpo: TRPOConfig | None = None
) -> None:
    """ValueError when ``config``'s rollout has fewer samples than learner ``name`` splits
    each iteration's batch into (TRPO's value minibatches, PPO's minibatches)."""
    if learner_name(name) == "ppo":
        (PPOConfig() if ppo is None else ppo).check_batch(config)
    else:
        (TRPOConfig() if trpo is None else trpo).check_batch(config)


@dataclasses.dataclass(frozen=True)
class LearnerConfig:
    """The learner part of a job's config (the sweep's ``RunConfig``, ``TrainRLConfig``,
    ``MakeDemosConfig``): which policy learner trains the policy (``name``: "trpo", the
    paper's, or "ppo") and each learner's static settings, of which the running one's are
    read. Written to config.json as ``{"name": ..., "trpo": {...}, "ppo": {...}}``
    (``learner_part`` reads it back; ``upgrade_learner_fields`` reads the older flat keys)."""

    name: str = DEFAULT_LEARNER
    trpo: TRPOConfig = TRPOConfig()
    ppo: PPOConfig = PPOConfig()

    def __post_init__(self):
        learner_name(self.name)
        for part, kind in (("trpo", TRPOConfig), ("ppo", PPOConfig)):
            if not isinstance(getattr(self, part), kind):
                fail(f"learner.{part}", f"must be a {kind.__name__}, got {getattr(self, part)!r}")
        if self.name == "ppo" and self.trpo.num_value_epochs != 1:
            fail(
                "learner.trpo.num_value_epochs",
                "is TRPO's value fit; PPO fits its value in its own epochs",
            )

    @property
    def settings(self) -> TRPOConfig | PPOConfig:
        """The running learner's own static settings."""
        return self.ppo if self.name == "ppo" else self.trpo

    def check_batch(self, rollout: RolloutConfig) -> None:
        """ValueError when ``rollout`` has fewer samples than the running learner splits each
        iteration's batch into."""
        check_batch(self.name, rollout, self.ppo, self.trpo)

    def replace(self, **changes) -> LearnerConfig:
        return dataclasses.replace(self, **changes)


def learner_part(value) -> LearnerConfig:
    """A job config's ``learner`` as its part: a ``LearnerConfig`` as it is, a learner's name
    as that learner with the default settings, a config.json object read strictly (a key
    that is no field: ConfigError naming it). ConfigError naming ``learner`` otherwise."""
    if isinstance(value, LearnerConfig):
        return value
    if isinstance(value, str):
        return LearnerConfig(name=value)
    if not isinstance(value, Mapping):
        fail("learner", f"must be a LearnerConfig or a learner's name, got {value!r}")
    values = dict(_known_keys(LearnerConfig, "learner", value))
    for part, kind in (("trpo", TRPOConfig), ("ppo", PPOConfig)):
        if isinstance(values.get(part), Mapping):
            fields = _known_keys(kind, f"learner.{part}", values[part])
            try:
                values[part] = kind(**fields)
            except ConfigError as error:
                raise error.nested(part).nested("learner") from None
    return LearnerConfig(**values)


class MovedSetting:
    """The class default of a deprecated init-only keyword (``AdversarialConfig.trpo`` and
    ``.ppo``, gone in 0.3): not given, as None was, but reading it as the old attribute raises
    one line naming where the setting lives now, where None would read as "the defaults" (TRPO
    takes a None config as its defaults) and drop the run's own settings without a word."""

    def __init__(self, old: str, new: str):
        self.__dict__.update(old=old, new=new)

    def __getattr__(self, name: str):
        raise AttributeError(f"{self.old} has moved: read {self.new}")

    def __bool__(self) -> bool:
        raise TypeError(f"{self.old} has moved: read {self.new}")

    def __repr__(self) -> str:
        return f"<{self.old}: moved to {self.new}>"


def learner_with_settings(
    value,
    where: str,
    trpo: TRPOConfig | MovedSetting | None = None,
    ppo: PPOConfig | MovedSetting | None = None,
    stacklevel: int = 3,
) -> LearnerConfig:
    """``value`` as its learner part (``learner_part``), with the settings that ``where`` (a
    trainer's config or function) used to take beside a learner's name: ``trpo`` and ``ppo``
    (None or a ``MovedSetting``: not given), each, when given, with a DeprecationWarning that
    names the new spelling (the keywords go in 0.3, with the other deprecated shims). The
    running learner's replace the part's own; the other learner's, which nothing read then
    either, are dropped (its checks against the running learner would refuse a call that
    worked). ``stacklevel`` as ``warnings.warn``'s, counted from here (3: the caller of the
    function that calls this)."""
    part = learner_part(value)
    given = {"trpo": trpo, "ppo": ppo}
    given = {
        name: settings
        for name, settings in given.items()
        if settings is not None and not isinstance(settings, MovedSetting)
    }
    if not given:
        return part
    spelled = ", ".join(f"{name}=..." for name in given)
    unread = [name for name in given if name != part.name]
    dropped = (
        f"; {', '.join(unread)}=... is not read by {part.name} and is dropped" if unread else ""
    )
    warnings.warn(
        f"{where}({spelled}) is deprecated and goes in 0.3: pass "
        f"{where}(learner=LearnerConfig(name=..., {spelled})) "
        f"(pngail_jax.config.learner.LearnerConfig){dropped}",
        DeprecationWarning,
        stacklevel=stacklevel,
    )
    return part.replace(**{name: given[name] for name in given if name == part.name})


def _known_keys(kind, where: str, data: Mapping) -> Mapping:
    unknown = sorted((key for key in data if key not in _field_names(kind)), key=str)
    if unknown:
        fail(where, f": unknown key(s) {unknown}; known: {', '.join(sorted(_field_names(kind)))}")
    return data


def _field_names(kind) -> set[str]:
    return {field.name for field in dataclasses.fields(kind)}


# The flat keys a sweep's config.json held before the learner part (issue 74), each with the
# TRPOConfig field it set.
FLAT_TRPO_KEYS = {
    "fisher": "fisher",
    "fisher_subsample": "fisher_subsample",
    "value_epochs": "num_value_epochs",
}


def upgrade_learner_fields(data: Mapping) -> dict:
    """A sweep's config.json from before the learner part in today's layout: its flat
    ``learner`` (a name, or absent: TRPO), ``fisher``, ``fisher_subsample`` and
    ``value_epochs`` as ``learner = {"name", "trpo", "ppo"}``, every setting it did not hold
    at the value it ran with (the defaults: PPO's settings could not be set then). Today's
    layout unchanged. Imports no JAX (``analysis`` reads records with it)."""
    learner = data.get("learner")
    flat = [key for key in FLAT_TRPO_KEYS if key in data]
    if isinstance(learner, Mapping) or (learner is None and not flat):
        return dict(data)
    upgraded = {key: value for key, value in data.items() if key not in FLAT_TRPO_KEYS}
    trpo = dataclasses.asdict(TRPOConfig())
    trpo.update({FLAT_TRPO_KEYS[key]: data[key] for key in flat})
    upgraded["learner"] = {
        "name": DEFAULT_LEARNER if learner is None else learner,
        "trpo": trpo,
        "ppo": dataclasses.asdict(PPOConfig()),
    }
    return upgraded


def upgrade_trainer_learner(trainer: Mapping) -> dict:
    """A sweep's ``resolved.trainer`` (its ``AdversarialConfig`` as written) from before the
    trainer's learner part in today's layout: the learner's name ``learner`` with ``trpo``
    and ``ppo`` beside it as ``learner = {"name", "trpo", "ppo"}``, the same values. Any
    other object unchanged (today's; an offline run's trainer, which has no learner)."""
    if not isinstance(trainer.get("learner"), str):
        return dict(trainer)
    upgraded = {key: value for key, value in trainer.items() if key not in ("trpo", "ppo")}
    upgraded["learner"] = {
        "name": trainer["learner"],
        "trpo": trainer.get("trpo"),
        "ppo": trainer.get("ppo"),
    }
    return upgraded
