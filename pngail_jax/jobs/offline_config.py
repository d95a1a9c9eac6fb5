"""``OfflineRunConfig``: what one offline grid is (methods x seeds on a task's
demonstrations, the gradient-step budget, the batch, ILID's discriminators and union), checked when
made, and ``load_offline_config``, the config an offline run in a folder began with. The
job that runs it is ``jobs.offline.run_offline``.
"""

from __future__ import annotations

import dataclasses
import numbers
from pathlib import Path

from pngail_jax.analysis.runs import read_run_config
from pngail_jax.config.budget import check_seeds
from pngail_jax.config.demonstrations import DemonstrationsConfig, demonstrations_part
from pngail_jax.config.settings import RunSettings
from pngail_jax.config.task import task_classifier, task_num_demos
from pngail_jax.config.training import task_settings
from pngail_jax.config.validation import (
    LABEL_RATIO_RANGE,
    NOISE_STD_RANGE,
    OPEN_UNIT_INTERVAL,
    fail,
    integer,
    layer_sizes,
    within,
)
from pngail_jax.jobs.errors import RunError
from pngail_jax.jobs.trainer_configs import sized_classifier
from pngail_jax.offline.family import OFFLINE
from pngail_jax.offline.ilid import check_union
from pngail_jax.offline.trainer import DEFAULT_OFFLINE_METHODS, OfflineConfig
from pngail_jax.storage.integrity import IntegrityError, read_json

PROGRAM = "offline"

# DWBC's discriminator updates in its codebase (one every 100th of 500,000 policy steps).
DWBC_CODEBASE_UPDATES = 5_000
# Fields whose default changed: what a config.json written before (without the field, or with
# the old default written) ran with. The spelling of each on the command line:
# ``former_default_flags``.
FORMER_DEFAULTS = {"dwbc_discriminator_updates": None}
# ``--dwbc-discriminator-updates every-100``: None, one update every 100th step.
EVERY_100TH = "every-100"


@dataclasses.dataclass(frozen=True)
class OfflineRunConfig:
    """One offline grid: methods x seeds on one task's demonstrations."""

    env: str = "Pendulum-v1"
    demos: str | None = None  # None: made once and cached, as the sweep's
    conf: str | None = None
    action_scale: float | None = None
    methods: tuple[str, ...] = DEFAULT_OFFLINE_METHODS
    seeds: int = 5
    seed: int = 0
    label_ratio: float = 0.2
    noise_std: float = 0.0
    gradient_steps: int = 50_000
    steps_per_iteration: int = 1_000
    eval_every: int = 5  # iterations (of steps_per_iteration) per evaluation
    chunk_iterations: int = 10
    batch_size: int = 256
    num_eval_episodes: int | None = None  # None: the task's (RunSettings)
    hidden_sizes: tuple[int, ...] = (100, 100)
    ilid_discriminator_steps: int = 100_000  # each of ILID's two, before its policy (codebase's)
    ilid_discriminator_learning_rate: float = 1e-5  # its codebase's Adam step size
    ilid_union: str = "intended"  # E+S; "released": padded with zero rows (offline_ilid)
    # Adam steps of DWBC's discriminator over the run, evenly spaced: its codebase's number
    # (5,000 of 500,000 steps; every 10th of 50,000). None: one every 100th policy step, its
    # codebase's cadence (500 at 50,000 steps), what every run did before 5,000 became the
    # default, and what a config.json without the field reads as (``FORMER_DEFAULTS``).
    dwbc_discriminator_updates: int | None = DWBC_CODEBASE_UPDATES

    def __post_init__(self):
        """Each field checked, in its stored type: ConfigError (a ValueError) naming it by
        its field, which the offline program turns into its flag."""
        self._check_methods()
        seeds, seed = check_seeds(self.seeds, self.seed)
        self._set("seeds", seeds)
        self._set("seed", seed)
        self._set("action_scale", self.demonstrations.action_scale)  # checked, as a float
        self.settings  # noqa: B018  (the task's row: an unknown task is refused)
        for name in ("gradient_steps", "steps_per_iteration", "eval_every",
                     "chunk_iterations", "batch_size", "ilid_discriminator_steps"):  # fmt: skip
            self._set(name, integer(name, getattr(self, name), minimum=1))
        block = self.steps_per_iteration * self.eval_every
        if self.gradient_steps % block:
            fail(
                "gradient_steps",
                f"({self.gradient_steps}) must be a multiple of steps_per_iteration x "
                f"eval_every = {block} (one evaluation each)",
            )
        self._set("label_ratio", within("label_ratio", self.label_ratio, LABEL_RATIO_RANGE))
        self._set("noise_std", within("noise_std", self.noise_std, NOISE_STD_RANGE))
        rate = self.ilid_discriminator_learning_rate
        rate = within("ilid_discriminator_learning_rate", rate, OPEN_UNIT_INTERVAL)
        self._set("ilid_discriminator_learning_rate", rate)
        check_union(self.ilid_union)
        if self.num_eval_episodes is not None:
            self._set("num_eval_episodes", integer("num_eval_episodes", self.num_eval_episodes, 1))
        self._set("hidden_sizes", layer_sizes("hidden_sizes", self.hidden_sizes))
        self._check_dwbc_updates()

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)  # frozen: a value stored in its own type

    def _check_methods(self) -> None:
        """Offline presets (or ``<preset>+bsc``), distinct, at least one."""
        if not isinstance(self.methods, list | tuple) or not self.methods:
            fail("methods", f"must be a non-empty list of offline methods, got {self.methods!r}")
        self._set("methods", tuple(self.methods))
        for method in self.methods:  # an unknown name: one line naming the known ones
            try:
                OFFLINE.check_method(method)
            except ValueError as error:
                fail("methods", f": {error}")
        if len(set(self.methods)) != len(self.methods):
            fail("methods", f"must be distinct, got {list(self.methods)}")

    def _check_dwbc_updates(self) -> None:
        """DWBC's discriminator updates: None (one every 100th step), or a positive count
        that divides the gradient steps (evenly spaced) or is at least their number (one
        update a step)."""
        updates = self.dwbc_discriminator_updates
        if updates is None:
            return
        if (
            isinstance(updates, bool) or not isinstance(updates, numbers.Integral) or updates < 1
            or (updates < self.gradient_steps and self.gradient_steps % updates)
        ):  # fmt: skip
            fail(
                "dwbc_discriminator_updates",
                f"must be a positive integer that divides gradient_steps "
                f"({self.gradient_steps}) or is at least it (one a step), got {updates!r}",
            )
        self._set("dwbc_discriminator_updates", int(updates))

    @property
    def dwbc_discriminator_every(self) -> int:
        """DWBC's discriminator steps on every this-many-th policy step."""
        if self.dwbc_discriminator_updates is None:  # the trainer's own: every 100th
            return OfflineConfig.dwbc_discriminator_every
        return max(1, self.gradient_steps // self.dwbc_discriminator_updates)

    @property
    def demonstrations(self) -> DemonstrationsConfig:
        """The demonstrations part (the files and their units; the normalised return's ends
        are the demonstrations' own), as the sweep's: what ``jobs.demonstrations`` reads."""
        return demonstrations_part(self)

    @property
    def settings(self) -> RunSettings:
        """The task's row of ``config.settings``: its environment's solver and evaluation
        episodes, as the sweep's on the same task."""
        return task_settings(self.env)

    def trainer_config(self, num_rows: int) -> OfflineConfig:
        """The offline trainer's static config on demonstrations of ``num_rows`` rows: the
        task's rows per split, classifier and evaluation episodes (``config.task``,
        ``config.settings``), as the sweep's on the same task."""
        num_demos = task_num_demos(self.env, num_rows)
        classifier = task_classifier(self.env)
        return OfflineConfig(
            num_iterations=self.gradient_steps // self.steps_per_iteration,
            steps_per_iteration=self.steps_per_iteration,
            eval_every=self.eval_every,
            num_eval_episodes=self.num_eval_episodes or self.settings.num_eval_episodes,
            batch_size=self.batch_size,
            hidden_sizes=self.hidden_sizes,
            num_demos=num_demos,
            classifier=sized_classifier(classifier, (self.label_ratio,), num_demos),
            ilid_discriminator_steps=self.ilid_discriminator_steps,
            ilid_union=self.ilid_union,
            dwbc_discriminator_every=self.dwbc_discriminator_every,
            components=OFFLINE.parts(self.methods),
        )


def offline_defaults() -> dict:
    """A default offline run's settings as its config.json writes them (tuples as lists), a
    field whose default changed at its former value (``FORMER_DEFAULTS``): what an offline
    record from before a field existed ran with."""
    values = dataclasses.asdict(OfflineRunConfig()) | FORMER_DEFAULTS
    return {key: list(v) if isinstance(v, tuple) else v for key, v in values.items()}


def former_default_flags(settings: dict) -> list[str]:
    """The flags that give a re-run of an offline record's command (its ``config`` part,
    ``settings``) what the record ran with where a default changed since: its command named
    no value, and today's default is another (``FORMER_DEFAULTS``)."""
    if settings.get("dwbc_discriminator_updates") is None:
        return ["--dwbc-discriminator-updates", EVERY_100TH]
    return []


def load_offline_config(out: str | Path) -> OfflineRunConfig:
    """The config an offline run in ``out`` began with (its config.json), or RunError."""
    path = Path(out) / "config.json"
    try:
        document = read_json(path, "offline run config")
        view = read_run_config(document)
        if view.program != PROGRAM:
            raise ValueError(f"written by {document.get('program')!r}")
        values = FORMER_DEFAULTS | dict(view.settings)  # a field it predates: as it ran
        for name in ("methods", "hidden_sizes"):
            values[name] = tuple(values[name])
        return OfflineRunConfig(**values)
    except (AttributeError, IntegrityError, KeyError, TypeError, ValueError) as error:
        raise RunError(
            f"cannot resume {out}: no offline run's config.json there ({error})"
        ) from None
