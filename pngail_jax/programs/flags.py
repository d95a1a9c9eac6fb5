"""One mapping from config fields to command-line flags.

Each ``FieldFlag`` ties a flag to a field of ``RunConfig`` (dotted for a nested config:
``settings.num_envs``, ``classifier.num_steps``): its name, help and how its text becomes the
field's value. The programs build their parsers from these tables (``add_flags``), read the
values given (``given_values``), and let the configs check them: a ``ConfigError`` names its
field, which ``flag_message`` turns into the flag, so an error reads in the command line's
words without rewriting its text.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from pngail_jax import envs
from pngail_jax.config.budget import PHASE_SIZES
from pngail_jax.config.learner import (
    FISHER_FORMS,
    LEARNERS,
    LearnerConfig,
    PPOConfig,
    TRPOConfig,
)
from pngail_jax.config.output import LOG_BACKENDS
from pngail_jax.config.settings import REFERENCE_SETTINGS, RunSettings, parse_solver, settings_for
from pngail_jax.config.task import TASK_CLASSIFIER_STEPS
from pngail_jax.config.validation import ConfigError
from pngail_jax.programs.cli import comma_floats, known_names, text_argument


@dataclasses.dataclass(frozen=True)
class FieldFlag:
    """A flag that sets ``field`` (``RunConfig``'s path, dotted for a nested config).

    ``convert(parser, flag, text)`` turns the flag's text into the value (default: argparse's
    ``type``); ``to_fields(value)`` gives the nested fields it sets (default: the one field),
    for a flag that sets several (``--solver``; ``also`` lists the others). ``subject``: how
    errors name it (default the flag).
    """

    field: str
    help: str
    flag: str | None = None
    type: Callable[[str], Any] | None = None
    convert: Callable[[argparse.ArgumentParser, str, str], Any] | None = None
    to_fields: Callable[[Any], dict[str, Any]] | None = None
    subject: str | None = None
    also: tuple[str, ...] = ()  # the other fields ``to_fields`` sets
    choices: Sequence[str] | None = None
    boolean: bool = False
    append: bool = False  # repeatable: the value is the list of every occurrence's text
    metavar: str | None = None

    @property
    def name(self) -> str:
        return self.flag or "--" + self.field.split(".")[-1].replace("_", "-")

    @property
    def dest(self) -> str:
        return self.name[2:].replace("-", "_")

    @property
    def section(self) -> str:
        """The nested config the field lives in (``""``: ``RunConfig`` itself)."""
        return self.field.rpartition(".")[0]

    def add_to(self, parser, defaults=None) -> None:
        """Adds the flag; ``{default}`` in its help reads the field's value in ``defaults``
        (a ``RunConfig``)."""
        help_text = self.help
        if defaults is not None and "{default" in help_text:
            value = defaults
            for part in self.field.split("."):
                value = getattr(value, part)
            help_text = help_text.format(default=value)
        options: dict[str, Any] = {"help": help_text}
        if self.boolean:
            options.update(action=argparse.BooleanOptionalAction, default=None)
        if self.append:
            options["action"] = "append"
        for key in ("type", "choices", "metavar"):
            if getattr(self, key) is not None:
                options[key] = getattr(self, key)
        parser.add_argument(self.name, **options)

    def fields(self, parser, text) -> dict[str, Any]:
        """The fields (last path part -> value) that the flag's parsed ``text`` sets."""
        value = text if self.convert is None else self.convert(parser, self.name, text)
        if self.to_fields is None:
            return {self.field.rpartition(".")[2]: value}
        try:
            return self.to_fields(value)
        except ValueError as error:
            parser.error(f"{self.name}: {error}")


def add_flags(parser, table: Sequence[FieldFlag], defaults=None) -> None:
    """Adds every flag of ``table``; ``defaults`` (a ``RunConfig``) fills in the help's
    ``{default}``."""
    for flag in table:
        flag.add_to(parser, defaults)


def given_values(parser, args, table: Sequence[FieldFlag]) -> dict[str, dict[str, Any]]:
    """The values of the flags given, by section: ``{"": {...}, "settings": {...}, ...}``."""
    values: dict[str, dict[str, Any]] = {}
    for flag in table:
        text = getattr(args, flag.dest)
        if text is not None:
            values.setdefault(flag.section, {}).update(flag.fields(parser, text))
    return values


def flag_message(error: ConfigError, tables: Sequence[Sequence[FieldFlag]]) -> str:
    """``error`` with its field called by its flag (its own name when no flag sets it)."""
    for table in tables:
        for flag in table:
            if error.field in (flag.field, *flag.also):
                return error.named(flag.subject or flag.name)
    return str(error)


def _methods(parser, flag: str, text: str) -> tuple[str, ...]:
    """Built-in or registered names, and ``package.module:preset`` ones (RunConfig imports
    and checks those)."""
    from pngail_jax.adversarial.methods import PRESETS

    outside = [item.strip() for item in str(text).split(",") if ":" in item]
    return tuple(known_names(parser, text, (*PRESETS, *outside), "method", flag=flag))


def _log_backends(parser, flag: str, text: str) -> tuple[str, ...]:
    return tuple(known_names(parser, text, LOG_BACKENDS, "log backend", flag=flag))


def _grid_axes(parser, flag: str, texts: list[str]) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """``FIELD=V1,V2,...`` per occurrence, as ``RunConfig.grid_axes`` (which checks the field
    and the values)."""
    if texts == ["none"]:  # clears a --config file's axes
        return ()
    axes = []
    for text in texts:
        field, equals, values = text.partition("=")
        if not equals or not field.strip():
            parser.error(f"{flag} takes FIELD=V1,V2,... (e.g. max_kl=0.005,0.01), got {text!r}")
        axes.append((field.strip(), comma_floats(parser, f"{flag} {field.strip()}", values)))
    return tuple(axes)


def _baseline(parser, flag: str, text: str) -> str | None:
    return None if text == "none" else text


def _absolute_file(parser, flag: str, text: str) -> str:
    """An existing file as an absolute path (a ``minari:<id>`` dataset as it is)."""
    if text.startswith("minari:"):
        return text
    if not Path(text).exists():
        parser.error(f"{flag} {text} does not exist")
    return str(Path(text).absolute())


TABLE = "(default: the table's)"

# The run settings (pngail_jax.config.settings.RunSettings); --settings picks the starting row.
SETTINGS_FLAGS = (
    FieldFlag("settings.num_envs", f"parallel envs per run {TABLE}", type=int),
    FieldFlag("settings.unroll_length", f"steps per env per iteration {TABLE}", type=int),
    FieldFlag("settings.eval_every", f"iterations between evaluations {TABLE}", type=int),
    FieldFlag("settings.num_eval_episodes", f"episodes per evaluation {TABLE}", type=int),
    FieldFlag(
        "settings.solver_iterations",
        f"MJX solver: 'own' (the task's), 'fast' (1/4) or 'I/L' iterations {TABLE}",
        flag="--solver",
        to_fields=parse_solver,
        also=("settings.ls_iterations",),
    ),
    FieldFlag(
        "settings.physics",
        "physics engine of gymnasium's MuJoCo tasks (Hopper-v4, ...): MuJoCo's C engine "
        "(float64, threaded; fastest on a CPU), MJX (accelerators) or MJX on MuJoCo Warp "
        '(NVIDIA GPUs; the extra pip install "pngail-jax[warp]") (default: c on a CPU, mjx '
        "on a GPU or TPU)",
        choices=envs.PHYSICS,
    ),
    FieldFlag(
        "settings.normalize_observations",
        f"running mean/std observation normalisation in the policy learner {TABLE}",
        boolean=True,
    ),
    FieldFlag(
        "settings.stagger_starts",
        f"cut each env's first episode at a random length, so that envs of a task that never "
        f"terminates are not in step {TABLE}",
        boolean=True,
    ),
)


def add_settings_flags(parser) -> None:
    group = parser.add_argument_group(
        "run settings (default: the environment's row of pngail_jax.config.settings.ENV_SETTINGS, "
        "see docs/performance.md)"
    )
    group.add_argument(
        "--settings",
        choices=("table", "reference"),
        help="start from the per-environment table or from the reference code's setting (25 "
        "envs x 200 steps, the task's own solver, 32 evaluation episodes every 10 iterations); "
        "the flags below override either (default: the table, or a --config file's settings)",
    )
    add_flags(group, SETTINGS_FLAGS)


def settings_from_flags(parser, args, env: str, base: RunSettings | None = None) -> RunSettings:
    """The ``RunSettings`` the settings flags select, from ``base`` (None: the table's row)
    unless ``--settings`` names the starting point; exits naming the flag on a bad value."""
    if args.settings == "reference":
        base = REFERENCE_SETTINGS
    elif args.settings == "table" or base is None:
        base = settings_for(env)
    changes = given_values(parser, args, SETTINGS_FLAGS).get("settings", {})
    try:
        settings = dataclasses.replace(base, **changes)
        if settings.physics is not None and env not in envs.GYM_TASKS:
            raise ConfigError(
                "settings.physics",
                f": only gymnasium's MuJoCo tasks ({', '.join(envs.GYM_TASKS)}) have a choice "
                f"of engine, not {env}",
            )
        if env == "Pendulum-v1" and settings.env_options:
            raise ConfigError("settings.solver_iterations", ": Pendulum-v1 has no MJX solver")
    except ConfigError as error:
        if not error.field.startswith("settings."):
            error = error.nested("settings")
        parser.error(flag_message(error, [SETTINGS_FLAGS]))
    return settings


# The sweep's flags for RunConfig fields (--env, --config, --preset and the output and
# multi-host flags are the program's own).
RUN_FLAGS = (
    FieldFlag(
        "methods",
        "comma-separated method names, from the list below or package.module:preset for "
        "your own (docs/methods.md) (default: the paper's seven)",
        convert=_methods,
    ),
    FieldFlag("seeds", "seeds per method and setting (default {default})", type=int),
    FieldFlag(
        "iterations",
        "policy iterations (TRPO or PPO updates) per run (default {default})",
        type=int,
    ),
    FieldFlag(
        "demos",
        "*_mixture.npy (authors' layout), *.npz, or minari:<dataset id> "
        "(default: made with pngail_jax.jobs.make_demos and cached)",
        type=text_argument,
        convert=_absolute_file,
    ),
    FieldFlag(
        "conf",
        "confidence file (default: the mixture's sibling; per episode for Minari)",
        type=text_argument,
        convert=_absolute_file,
    ),
    FieldFlag(
        "confidence_field", "Minari: the per-episode field holding confidences (default: none)"
    ),
    FieldFlag(
        "action_scale",
        "multiplies stored actions (default: an authors' file's known scale, 2 for their "
        "Pendulum file, whose torques are stored halved; else 1)",
        type=float,
    ),
    FieldFlag(
        "optimal_return",
        "the normalised return's 1: the best return the task allows (default: the "
        "demonstrations' own, Table 3 for an authors' file; none for a file of rows)",
        type=float,
    ),
    FieldFlag(
        "random_return",
        "the normalised return's 0 (default: the demonstrations' own; with --optimal-return "
        "alone, measured from uniform random actions)",
        type=float,
    ),
    FieldFlag(
        "num_demos",
        "rows per split, n_c + n_u (default: the task's Table 3 size, capped at the "
        "demonstrations' rows; every row for a task without one)",
        type=int,
    ),
    FieldFlag(
        "label_ratios",
        "comma-separated values: a grid axis (default 0.2)",
        flag="--label-ratio",
        convert=comma_floats,
        subject="--label-ratio values",
    ),
    FieldFlag(
        "noise_stds",
        "confidence noise std, comma-separated: a grid axis (default 0)",
        flag="--noise",
        convert=comma_floats,
        subject="--noise values",
    ),
    FieldFlag(
        "grid_axes",
        "another grid axis, repeatable: a per-cell value (a discriminator or learner "
        "hyperparameter, e.g. max_kl or clip_eps, or a MethodSpec coefficient, e.g. "
        "pn_coef) and its values; every axis multiplies the grid; --grid none clears a "
        "--config file's (default: none)",
        flag="--grid",
        convert=_grid_axes,
        append=True,
        metavar="FIELD=V1,V2",
    ),
    FieldFlag(
        "baseline",
        "the summary's probability of improvement: of every other method over this one; "
        "'none' clears a --config file's (default: of PN-GAIL over every other method)",
        convert=_baseline,
    ),
    FieldFlag("seed", "base PRNG seed (default 0)", type=int),
    FieldFlag(
        "chunk_iterations",
        "iterations per compiled chunk: progress, checkpoint, log (default {default})",
        type=int,
    ),
    FieldFlag(
        "classifier.num_steps",
        "confidence classifier steps (default {default:,}; "
        f"{TASK_CLASSIFIER_STEPS['Walker2d']:,} on Walker2d, the paper's)",
        flag="--classifier-steps",
        type=int,
    ),
    FieldFlag("bsc_eps", "BSC's clip (default 0.01; 0.05 on Walker2d, the paper's)", type=float),
    FieldFlag(
        "phase_sizes",
        "the appendix baselines' training phases (T-REX's and D-REX's reward fits, D-REX's "
        "cloning, CAIL's rounds, f-IRL's discriminator): codebase, their codebases' sizes, or "
        "check, small sizes that only show a method runs (default: codebase; the check "
        "preset's: check)",
        choices=PHASE_SIZES,
    ),
    FieldFlag(
        "cpu_devices",
        "on a CPU, split it into this many XLA devices and shard the grid over them "
        "(default 1: on 2 cores one device already uses both, and 2 measured no faster)",
        type=int,
    ),
    FieldFlag(
        "log",
        f"comma-separated logging backends, from {', '.join(LOG_BACKENDS)}, fed once per chunk "
        "(default: none)",
        convert=_log_backends,
    ),
)


_TRPO, _PPO = TRPOConfig(), PPOConfig()
# The policy learner's part (pngail_jax.config.learner.LearnerConfig) for every program that
# trains a policy (the sweep, train_rl, make_demos): its name, TRPO's settings and PPO's.
LEARNER_FLAGS = (
    FieldFlag(
        "learner.name",
        "the policy learner: trpo (the paper's) or ppo (docs/ppo.md) (default trpo)",
        flag="--learner",
        choices=LEARNERS,
        also=("learner",),
    ),
    FieldFlag(
        "learner.trpo.fisher",
        "TRPO's Fisher-vector product: the same matrix either way (the Hessian of the mean KL "
        "at the current policy); hessian is the reference's form, gauss_newton 1.7x faster "
        f"here (default {_TRPO.fisher})",
        flag="--fisher",
        choices=FISHER_FORMS,
    ),
    FieldFlag(
        "learner.trpo.fisher_subsample",
        f"TRPO's Fisher products on every k-th time step (default {_TRPO.fisher_subsample}: all)",
        flag="--fisher-subsample",
        type=int,
    ),
    FieldFlag(
        "learner.trpo.num_value_epochs",
        "passes of TRPO's value fit over each batch (default "
        f"{_TRPO.num_value_epochs}, the reference's; docs/performance.md)",
        flag="--value-epochs",
        type=int,
    ),
    FieldFlag(
        "learner.ppo.num_epochs",
        f"PPO's epochs over each batch (default {_PPO.num_epochs})",
        flag="--ppo-epochs",
        type=int,
    ),
    FieldFlag(
        "learner.ppo.num_minibatches",
        f"PPO's minibatches per epoch (default {_PPO.num_minibatches})",
        flag="--ppo-minibatches",
        type=int,
    ),
    FieldFlag(
        "learner.ppo.clip_value_loss",
        "PPO's clipped value loss (default: on)",
        flag="--ppo-clip-value-loss",
        boolean=True,
    ),
    FieldFlag(
        "learner.ppo.anneal_learning_rate",
        "PPO's learning rate annealed linearly to 0 over the run (default: on)",
        flag="--ppo-anneal-learning-rate",
        boolean=True,
    ),
    FieldFlag(
        "learner.ppo.normalize_rewards",
        "PPO's rewards divided by the running std of the discounted return, clipped to "
        "[-10, 10] (default: on)",
        flag="--ppo-normalize-rewards",
        boolean=True,
    ),
)


def add_learner_flags(parser) -> None:
    group = parser.add_argument_group(
        "policy learner (pngail_jax.config.learner.LearnerConfig; each learner reads its own)"
    )
    add_flags(group, LEARNER_FLAGS)


def learner_from_flags(parser, args, base: LearnerConfig | None = None) -> LearnerConfig:
    """The ``LearnerConfig`` the learner flags give, from ``base`` (None: the defaults);
    exits naming the flag of a bad value."""
    base = base or LearnerConfig()
    given = given_values(parser, args, LEARNER_FLAGS)
    try:
        parts = {}
        for part in ("trpo", "ppo"):
            try:
                parts[part] = dataclasses.replace(
                    getattr(base, part), **given.get(f"learner.{part}", {})
                )
            except ConfigError as error:
                raise error.nested(part).nested("learner") from None
        return LearnerConfig(name=given.get("learner", {}).get("name", base.name), **parts)
    except ConfigError as error:
        parser.error(flag_message(error, [LEARNER_FLAGS]))
