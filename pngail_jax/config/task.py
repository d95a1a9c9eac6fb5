"""The task part of a run's config: the paper's per-task settings as tables keyed by
``envs.task_family`` (Hopper-v4 and Brax's Hopper share a row), and the values a run of a
task takes from them unless it sets its own: rows per split (``task_num_demos``), BSC's clip
(``task_bsc_eps``) and the classifier (``task_classifier``). The sweep's ``RunConfig`` and the
offline job's config both read them here. Imports no JAX (``envs`` gives the task's name)."""

from __future__ import annotations

from pngail_jax import envs
from pngail_jax.config.classifier import DEFAULT_BSC_EPS, ClassifierConfig

# BSC's clip per task where the paper departs from 0.01 (appendix C.2: 0.05 on Walker2d).
TASK_BSC_EPS = {"Walker2d": 0.05}
# Classifier steps per task where the paper departs from 25,000 (appendix C.2).
TASK_CLASSIFIER_STEPS = {"Walker2d": 50_000}
# Rows per split, n_c + n_u, per task (the paper's Table 3): ``num_demos=None`` takes these,
# capped at the demonstrations' row count.
TASK_NUM_DEMOS = {
    "Pendulum-v1": 1000,
    "Ant": 600,
    "HalfCheetah": 2500,
    "Hopper": 100,
    "Swimmer": 25,
    "Walker2d": 2000,
}


def task_classifier(env: str) -> ClassifierConfig:
    """The paper's classifier settings for ``env`` (``TASK_CLASSIFIER_STEPS``, else the
    reference code's 25,000 steps)."""
    default = ClassifierConfig()
    return ClassifierConfig(
        num_steps=TASK_CLASSIFIER_STEPS.get(envs.task_family(env), default.num_steps)
    )


def task_bsc_eps(env: str, bsc_eps: float | None = None) -> float:
    """BSC's clip: ``bsc_eps``, else the task's (``TASK_BSC_EPS``, else 0.01)."""
    if bsc_eps is not None:
        return bsc_eps
    return TASK_BSC_EPS.get(envs.task_family(env), DEFAULT_BSC_EPS)


def task_num_demos(env: str, num_rows: int, num_demos: int | None = None) -> int:
    """Rows per split for demonstrations of ``num_rows`` rows: ``num_demos``, or the task's
    paper size (``TASK_NUM_DEMOS``) capped at ``num_rows``, or every row."""
    if num_demos is not None:
        return num_demos
    return min(num_rows, TASK_NUM_DEMOS.get(envs.task_family(env), num_rows))
