"""The one place a run's config becomes the trainers' static configs: ``adversarial_config``
turns a sweep's ``RunConfig`` into the ``AdversarialConfig`` its trainer is built with, and
``sized_classifier`` gives the confidence classifier the unlabelled batch width a grid's label
ratios need (the offline job's trainer config takes it too). The config itself
(``pngail_jax.config``) imports no trainer for this: checking a ``RunConfig`` checks its
learner's batch (``config.training``), and the trainer's config is built once, here, when
the run is built (``jobs.build``, ``jobs.early_rewards``)."""

from __future__ import annotations

import dataclasses

from pngail_jax.adversarial import cail, ranking
from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.firl import FirlConfig
from pngail_jax.adversarial.methods import trains_classifier
from pngail_jax.adversarial.trainer import AdversarialConfig
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.budget import CHECK_PHASE_SIZES
from pngail_jax.config.run_config import RunConfig


def sized_classifier(
    classifier: ClassifierConfig, label_ratios: tuple[float, ...], num_demos: int | None
) -> ClassifierConfig:
    """``classifier`` with its unlabelled batch as wide as the grid's smallest label ratio
    needs on ``num_demos`` rows, no wider (as given when its batch size is set, or when the
    row count is not known yet)."""
    if classifier.unlabelled_batch_size is not None or num_demos is None:
        return classifier
    width = max(
        classifier.unlabelled_rows_per_step(num_demos, max(round(r * num_demos), 1))
        for r in label_ratios
    )
    return dataclasses.replace(classifier, max_unlabelled_batch_size=width)


def adversarial_config(config: RunConfig, num_rows: int | None = None) -> AdversarialConfig:
    """The static configuration of the trainer ``config`` builds on demonstrations of
    ``num_rows`` rows (None: ``num_demos`` as given, every row when None)."""
    num_demos = config.num_demos if num_rows is None else config.task_num_demos(num_rows)
    return AdversarialConfig(
        rollout=config.settings.rollout_config(config.iterations),
        learner=config.learner,
        classifier=sized_classifier(config.classifier, config.label_ratios, num_demos),
        num_demos=num_demos,
        discriminator_hidden_sizes=config.discriminator_hidden_sizes,
        phases=ADVERSARIAL.parts(config.methods),
        gradient_penalty=config.uses_gradient_penalty,
        confidence_classifier=trains_classifier(config.methods, config.grid_axes),
        **phase_configs(config.phase_sizes, config.env),
    )


def phase_configs(phase_sizes: str, env: str) -> dict:
    """The appendix phases' static configs of a run on ``env``: their codebases' (f-IRL's for
    the task, the others the trainer's defaults) for "codebase"; for "check", the same with
    the sizes of ``CHECK_PHASE_SIZES`` (every other setting of each phase kept)."""
    firl = FirlConfig.for_env(env)
    if phase_sizes == "codebase":
        return {"firl": firl}
    sizes = CHECK_PHASE_SIZES
    drex = ranking.DrexConfig()
    fit = {"num_steps": sizes["ranking_steps"], "pairs_per_step": sizes["ranking_pairs_per_step"]}
    return {
        "firl": dataclasses.replace(
            firl, discriminator_iterations=sizes["firl_discriminator_iterations"]
        ),
        "ranking": dataclasses.replace(ranking.RankingConfig(), **fit),
        "drex": dataclasses.replace(
            drex,
            bc=dataclasses.replace(drex.bc, num_steps=sizes["drex_bc_steps"]),
            rollouts_per_level=sizes["drex_rollouts_per_level"],
            ranking=dataclasses.replace(drex.ranking, **fit),
        ),
        "cail": dataclasses.replace(cail.CAILConfig(), num_rounds=sizes["cail_rounds"]),
    }
