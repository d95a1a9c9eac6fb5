"""``RunConfig``: everything that defines a sweep, frozen and validated, saved as JSON.

The command line (``python -m experiments.sweep``) only fills one in; Python users build it
directly (``RunConfig(env="Hopper", methods=("gail", "pngail"))``) or from a preset
(``RunConfig.preset("paper", demos="...")``). ``to_dict`` / ``from_dict`` (and ``from_json``)
round-trip it, so a saved ``config.json`` starts a new run (``--config FILE``) or continues one
(``--resume DIR``). ``config_record.provenance()`` adds what a saved run should remember of
where it ran.

Every field is checked when a config is made, from Python or from a file: a wrong type, a NaN
or infinite number or a count below 1 raises ``pngail_jax.config.validation.ConfigError`` naming the
field (the sweep names its flag instead), and an unknown key a ValueError naming the key, so a
valid config holds exactly its annotated types.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from pngail_jax.config.budget import check_phase_sizes
from pngail_jax.config.classifier import ClassifierConfig
from pngail_jax.config.demonstrations import DemonstrationsConfig, demonstrations_part
from pngail_jax.config.grid_axes import check_grid_axes
from pngail_jax.config.learner import LearnerConfig, learner_part
from pngail_jax.config.methods import resolve
from pngail_jax.config.presets import METHOD_NAMES
from pngail_jax.config.run_config_checks import check_names
from pngail_jax.config.saved import upgrade_saved_config
from pngail_jax.config.settings import RunSettings
from pngail_jax.config.task import (  # noqa: F401  (the tables, importable from here too)
    TASK_BSC_EPS,
    TASK_CLASSIFIER_STEPS,
    TASK_NUM_DEMOS,
    task_bsc_eps,
    task_classifier,
    task_num_demos,
)
from pngail_jax.config.training import check_training
from pngail_jax.config.validation import (
    LABEL_RATIO_RANGE,
    NOISE_STD_RANGE,
    ConfigError,
    fail,
    float_axis,
    integer,
    layer_sizes,
    real,
)

# What a saved config.json holds besides the config's fields (pngail_jax.jobs.record writes them);
# RunConfig.from_dict ignores these and refuses any other key that is not a field.
RECORD_KEYS = ("resolved", "provenance")


@dataclasses.dataclass(frozen=True)
class RunConfig:
    """One sweep: a grid of methods x seeds x label ratios x noise levels on one environment.

    The defaults are the smoke scale (a few minutes on a 2-core CPU); ``settings`` defaults to
    the environment's row of ``pngail_jax.config.settings.ENV_SETTINGS``.
    """

    env: str = "Pendulum-v1"
    methods: tuple[str, ...] = METHOD_NAMES
    seeds: int = 3
    iterations: int = 300
    label_ratios: tuple[float, ...] = (0.2,)
    noise_stds: tuple[float, ...] = (0.0,)
    # More grid axes: ((field, (value, ...)), ...), each field a per-cell value
    # (pngail_jax.config.grid_axes.GRID_AXES: discriminator and TRPO hyperparameters, MethodSpec
    # coefficients); the grid is the product of every axis.
    grid_axes: tuple[tuple[str, tuple[float, ...]], ...] = ()
    # The summary's probability of improvement: of each method over this one (None: of
    # PN-GAIL over each other method).
    baseline: str | None = None
    seed: int = 0  # base PRNG seed; cell keys are fold_in(key(seed), cell seed)
    # Demonstrations: a *_mixture.npy (authors' layout), an .npz, or "minari:<dataset id>";
    # None: made with pngail_jax.jobs.make_demos and cached (jobs.demonstrations).
    demos: str | None = None
    conf: str | None = None  # confidence file (default: the mixture's sibling)
    confidence_field: str | None = None  # Minari: the per-episode field holding confidences
    # Multiplies stored actions. None: an authors' file's known scale (2 for their Pendulum
    # file, whose torques are stored halved), else 1 (``demos.load_released``).
    action_scale: float | None = None
    # The normalised return's ends, (R - random) / (optimal - random). None: the
    # demonstrations' own (the paper's Table 3 for an authors' file, measured for made ones);
    # an optimal return without a random one: the random one is measured (uniform actions).
    random_return: float | None = None
    optimal_return: float | None = None
    # Rows per split, n_c + n_u. None: the task's paper size (TASK_NUM_DEMOS) capped at the
    # demonstrations' rows; every row for a task without one.
    num_demos: int | None = None
    chunk_iterations: int = 50  # iterations per compiled chunk (progress + checkpoint)
    settings: RunSettings | None = None
    classifier: ClassifierConfig | None = None  # None: the task's (task_classifier)
    bsc_eps: float | None = None  # None: the task's (TASK_BSC_EPS, else 0.01)
    # The policy learner (pngail_jax.config.learner.LearnerConfig): its name, "trpo" (the
    # paper's) or "ppo", and each one's static settings (TRPO's Fisher product and value fit,
    # PPO's epochs and minibatches); a name alone is that learner at its defaults. The
    # rollout's shape and the networks are the settings' either way.
    learner: LearnerConfig = LearnerConfig()
    discriminator_hidden_sizes: tuple[int, ...] = (100, 100)
    # The appendix baselines' training phases: "codebase", their codebases' sizes (results),
    # or "check", the small sizes of pngail_jax.config.budget.CHECK_PHASE_SIZES (the check
    # preset's: a look at whether every method runs, not a result).
    phase_sizes: str = "codebase"
    cpu_devices: int | None = None  # split a CPU into this many XLA devices
    log: tuple[str, ...] = ()  # "tensorboard" and/or "wandb"
    preset_name: str | None = None  # the preset this config started from, for the record

    def __post_init__(self):
        # Frozen: fields are normalised through object.__setattr__ (lists from JSON -> tuples,
        # NumPy numbers -> Python ones, ints in float fields -> floats), so a valid config holds
        # exactly the types its annotations name and its JSON reads back equal.
        for name in _TUPLE_FIELDS:
            value = getattr(self, name)
            self._set(name, tuple(value) if isinstance(value, list | tuple) else (value,))
        check_training(self)  # env, settings, the budget and the learner, as every job's
        self._check_classifier()
        self._check_numbers()
        if self.preset_name is not None and (
            not isinstance(self.preset_name, str) or not self.preset_name
        ):
            fail("preset_name", f"must be a non-empty string or None, got {self.preset_name!r}")
        check_names(self)

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)

    def _check_classifier(self) -> None:
        """The classifier (None: the task's)."""
        if self.classifier is None:
            self._set("classifier", task_classifier(self.env))
        if not isinstance(self.classifier, ClassifierConfig):
            fail(
                "classifier",
                "must be a pngail_jax.confidence.ClassifierConfig, "
                f"got {type(self.classifier).__name__}",
            )
        self._set("classifier", ClassifierConfig(**_classifier_fields(_fields_of(self.classifier))))

    def _check_numbers(self) -> None:
        """Counts, grid axes and the optional numbers, each in its stored type."""
        self._set("chunk_iterations", integer("chunk_iterations", self.chunk_iterations, 1))
        for name, minimum, below in (("num_demos", 2, 2**31), ("cpu_devices", 1, None)):
            if getattr(self, name) is not None:  # num_demos: a row index is an int32
                self._set(name, integer(name, getattr(self, name), minimum, below=below))
        sizes = layer_sizes("discriminator_hidden_sizes", self.discriminator_hidden_sizes)
        self._set("discriminator_hidden_sizes", sizes)
        ratios = float_axis(
            "label_ratios", self.label_ratios, *LABEL_RATIO_RANGE, name="label ratios"
        )
        noise = float_axis("noise_stds", self.noise_stds, *NOISE_STD_RANGE, name="noise stds")
        self._set("label_ratios", ratios)
        self._set("noise_stds", noise)
        for name, value in dataclasses.asdict(self.demonstrations).items():
            self._set(name, value)  # the part's checks, its numbers as Python floats
        if self.bsc_eps is not None:
            self._set("bsc_eps", real("bsc_eps", self.bsc_eps, "lie in (0, 0.5)"))
            if not 0 < self.bsc_eps < 0.5:
                fail("bsc_eps", f"must lie in (0, 0.5), got {self.bsc_eps!r}")
        self._set("grid_axes", check_grid_axes(self.grid_axes))
        self._set("phase_sizes", check_phase_sizes(self.phase_sizes))

    @classmethod
    def preset(cls, name: str, **overrides) -> RunConfig:
        """The named preset (``PRESETS_BY_NAME``) with ``overrides``."""
        if name not in PRESETS_BY_NAME:
            raise ValueError(f"unknown preset {name!r}; available: {', '.join(PRESETS_BY_NAME)}")
        return cls(**{**PRESETS_BY_NAME[name], "preset_name": name, **overrides})

    def replace(self, **overrides) -> RunConfig:
        """A validated copy with ``overrides``. A new environment gets its own settings row
        and classifier unless ``settings`` / ``classifier`` are given too."""
        if overrides.get("env", self.env) != self.env:
            overrides.setdefault("settings", None)
            overrides.setdefault("classifier", None)
        return dataclasses.replace(self, **overrides)

    @property
    def demonstrations(self) -> DemonstrationsConfig:
        """The demonstrations part of this run (its files, their units, the normalised
        return's ends), whose fields config.json keeps flat."""
        return demonstrations_part(self)

    @property
    def task_bsc_eps(self) -> float:
        return task_bsc_eps(self.env, self.bsc_eps)

    @property
    def num_settings(self) -> int:
        return (
            len(self.label_ratios)
            * len(self.noise_stds)
            * math.prod(len(values) for _, values in self.grid_axes)
        )

    def task_num_demos(self, num_rows: int) -> int:
        """Rows per split for demonstrations of ``num_rows`` rows: ``num_demos``, or the
        task's paper size (``TASK_NUM_DEMOS``) capped at ``num_rows``, or every row."""
        return task_num_demos(self.env, num_rows, self.num_demos)

    @property
    def uses_gradient_penalty(self) -> bool:
        """Whether a method or a grid axis gives some cell a gradient penalty, which only then
        is compiled (it costs a second pass through the discriminator)."""
        by_method = any(
            resolve(name).coefficients.get("gradient_penalty_coef", 0.0) for name in self.methods
        )
        by_axis = any(
            value
            for field, values in self.grid_axes
            if field == "gradient_penalty_coef"
            for value in values
        )
        return bool(by_method or by_axis)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RunConfig:
        """The config of ``to_dict`` (or of a ``config.json`` of any layout, read by
        ``upgrade_saved_config`` first: today's ``config`` unwrapped, an old layout upgraded;
        its ``RECORD_KEYS`` sections, ``resolved`` and ``provenance``, are ignored).

        Strict, because a hand-edited file is easy to get wrong: ValueError naming the key on
        a key that is not a field (a typo would otherwise be dropped silently) and on a value
        of the wrong type (``"3"`` for ``seeds``, a number for ``methods``). A missing key
        takes the field's default, and missing ``settings`` keys ``RunSettings``' defaults
        (the reference setting), as in files written before the field existed.
        """
        if not isinstance(data, Mapping):
            raise ValueError(f"a run config is a JSON object of fields, got {type(data).__name__}")
        data = upgrade_saved_config(data)
        fields = {field.name for field in dataclasses.fields(cls)}
        unknown = sorted((key for key in data if key not in fields | set(RECORD_KEYS)), key=str)
        if unknown:
            raise ValueError(
                f"unknown key(s) {unknown}; a run config's keys: {', '.join(sorted(fields))}"
            )
        values = {key: value for key, value in data.items() if key in fields}
        if isinstance(values.get("settings"), Mapping):
            values["settings"] = _nested(RunSettings, "settings", values["settings"])
        if isinstance(values.get("learner"), Mapping):
            values["learner"] = learner_part(values["learner"])
        if isinstance(values.get("classifier"), Mapping):
            classifier = _nested_fields(ClassifierConfig, "classifier", values["classifier"])
            values["classifier"] = ClassifierConfig(**_classifier_fields(classifier))
        return cls(**values)

    @classmethod
    def from_json(cls, path: str | Path) -> RunConfig:
        path = Path(path)
        try:
            data = json.loads(path.read_text())
            return cls.from_dict(data)
        except (OSError, json.JSONDecodeError, TypeError) as error:
            raise ValueError(f"{path}: not a run config ({error})") from None
        except ValueError as error:
            raise ValueError(f"{path}: {error}") from None


PRESETS_BY_NAME: dict[str, dict[str, Any]] = {
    # A first look: every method runs, in about two minutes on a 2-core CPU (Pendulum-v1);
    # the same scale as experiments.paper's check preset.
    # The appendix baselines' phases at their small check sizes (``phase_sizes``).
    "check": {"iterations": 20, "seeds": 2, "chunk_iterations": 10, "phase_sizes": "check"},
    # A few minutes on a 2-core CPU (the command line's default).
    "smoke": {"iterations": 300, "seeds": 3, "chunk_iterations": 50},
    # The paper's budget: 5,000 TRPO iterations, 5 seeds (a GPU run).
    "paper": {"iterations": 5_000, "seeds": 5, "chunk_iterations": 250},
}


# -- field checks (pngail_jax.config.validation): each returns the value in its stored type -------

_TUPLE_FIELDS = ("methods", "label_ratios", "noise_stds", "log", "discriminator_hidden_sizes")


def _fields_of(instance) -> dict[str, Any]:
    return {field.name: getattr(instance, field.name) for field in dataclasses.fields(instance)}


def _classifier_fields(values: dict[str, Any]) -> dict[str, Any]:
    """``ClassifierConfig`` keyword arguments checked and in their stored types (its own
    checks let a bool, a float learning rate of NaN or a negative width through)."""
    checked = dict(values)

    def check(name: str, test, *args):
        checked[name] = test(f"classifier.{name}", checked[name], *args, name=_CLASSIFIER + name)

    for name in (
        "num_steps", "labelled_batch_size", "unlabelled_batch_size", "max_unlabelled_batch_size"
    ):  # fmt: skip
        if name == "unlabelled_batch_size" and checked.get(name) is None:
            continue  # the authors' int(n_u / n_c)
        if name in checked:
            check(name, integer, 1)
    if "learning_rate" in checked:
        check("learning_rate", real)
        if checked["learning_rate"] <= 0:
            fail(
                "classifier.learning_rate",
                f"must be finite and positive, got {values['learning_rate']!r}",
                name=_CLASSIFIER + "learning_rate",
            )
    if "dropout_rate" in checked:
        check("dropout_rate", real, "lie in [0, 1)")
        if not 0 <= checked["dropout_rate"] < 1:
            fail(
                "classifier.dropout_rate",
                f"must lie in [0, 1), got {values['dropout_rate']!r}",
                name=_CLASSIFIER + "dropout_rate",
            )
    if "hidden_sizes" in checked:
        check("hidden_sizes", layer_sizes)
    return checked


_CLASSIFIER = "ClassifierConfig."


def _nested_fields(cls, where: str, data: Mapping) -> dict[str, Any]:
    """The keys of a nested config's JSON object (``settings``, ``classifier``); ConfigError
    naming ``where`` and the key on a key that is not one of ``cls``' fields."""
    fields = {field.name for field in dataclasses.fields(cls)}
    unknown = sorted((key for key in data if key not in fields), key=str)
    if unknown:
        fail(where, f": unknown key(s) {unknown}; known: {', '.join(sorted(fields))}")
    return dict(data)


def _nested(cls, where: str, data: Mapping):
    try:
        return cls(**_nested_fields(cls, where, data))
    except ConfigError as error:
        raise error.nested(where) from None
    except TypeError as error:
        fail(where, f": {error}")
