"""The fields every job that trains a policy shares, checked once: the task (``env``) and its
run settings, the budget (``iterations``, ``seeds``, ``seed``) and the learner part. The
sweep's ``RunConfig``, ``TrainRLConfig`` and ``MakeDemosConfig`` call ``check_training``
from their ``__post_init__``; each keeps its own defaults (a sweep runs longer than a
policy trained for demonstrations), not its own checks."""

from __future__ import annotations

from pngail_jax import envs
from pngail_jax.config.budget import check_eval_interval, check_seeds
from pngail_jax.config.learner import learner_part
from pngail_jax.config.settings import RunSettings, settings_for
from pngail_jax.config.validation import fail, integer


def check_training(config, **table_changes) -> None:
    """Normalises and checks ``config``'s training fields in place (a frozen dataclass's,
    from its ``__post_init__``): ``settings`` None takes the task's row of
    ``config.settings.ENV_SETTINGS`` with ``table_changes`` (``eval_every=10``, say); a
    learner given by name is that learner's part with its defaults; the counts become Python
    ints. ConfigError naming the field; a learner whose batch the rollout cannot fill:
    ValueError (it reads several fields)."""
    if not isinstance(config.env, str) or not config.env:
        fail("env", f"must be an environment name, got {config.env!r}")
    table = task_settings(config.env, **table_changes)  # refuses an unknown task
    if config.settings is None:
        _set(config, "settings", table)
    elif not isinstance(config.settings, RunSettings):
        fail(
            "settings",
            "must be a pngail_jax.config.settings.RunSettings (None: the environment's row), "
            f"got {type(config.settings).__name__}",
        )
    seeds, seed = check_seeds(config.seeds, config.seed)
    _set(config, "seeds", seeds)
    _set(config, "seed", seed)
    _set(config, "iterations", integer("iterations", config.iterations, minimum=1))
    _set(config, "learner", learner_part(config.learner))
    check_engine(config.env, config.settings)
    check_eval_interval(config.iterations, config.settings.eval_every)
    # The learner's batch against its minibatches: the one check of the trainer's config that
    # reads several fields (the trainer's config is built once, with the run).
    config.learner.check_batch(config.settings.rollout_config(config.iterations))


def task_settings(env: str, **changes) -> RunSettings:
    """The table's settings of ``env`` (with ``changes``); ConfigError naming ``env`` when
    ``envs.make`` does not know it."""
    try:
        return settings_for(env, **changes)
    except (TypeError, ValueError) as error:  # a relative module name (".x:f") is a TypeError
        fail("env", f": {error}")


def check_engine(env: str, settings: RunSettings) -> None:
    """The settings' physics engine and solver caps apply to ``env``: only gymnasium's MuJoCo
    tasks choose an engine, and Pendulum-v1 has no solver."""
    if settings.physics is not None and env not in envs.GYM_TASKS:
        fail(
            "settings.physics",
            f": only gymnasium's MuJoCo tasks ({', '.join(envs.GYM_TASKS)}) have a choice of "
            f"engine, not {env}",
            name="RunSettings.physics",
        )
    if env == "Pendulum-v1" and settings.env_options:
        cap = next(iter(settings.env_options))  # the first solver cap set
        fail(
            f"settings.{cap}",
            ": Pendulum-v1 has no MJX solver (its solver caps stay None)",
            name=f"RunSettings.{cap}",
        )


def _set(config, name: str, value) -> None:
    object.__setattr__(config, name, value)  # a frozen config normalises its own fields
