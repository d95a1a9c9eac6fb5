"""The learner part of a run's config, as plain data: the policy learners' names, TRPO's
Fisher forms and their default, and the checks of a config's learner fields, written once for
every job's config (the sweep's ``RunConfig``, ``TrainRLConfig``, ``MakeDemosConfig``).
Imports no JAX: ``pngail_jax.rl`` builds the learners these name (``rl.learners``) and
``rl.trpo.TRPOConfig`` takes its Fisher default from here."""

from __future__ import annotations

from pngail_jax.config.validation import fail, is_among

# "trpo" (the paper's, the default) and "ppo" (pngail_jax.rl.learners builds them).
LEARNERS = ("trpo", "ppo")
DEFAULT_LEARNER = "trpo"
# TRPO's Fisher-vector product: "gauss_newton" (J^T M J v, one jvp and one vjp, the default
# everywhere: library, sweep, train_rl) or "hessian" (the reference's second-order form).
FISHER_FORMS = ("gauss_newton", "hessian")
DEFAULT_FISHER = "gauss_newton"


def check_learner(learner, *, fisher=DEFAULT_FISHER, value_epochs=1) -> None:
    """A config's learner fields: the learner's name, TRPO's Fisher form, and TRPO's value
    epochs left at 1 under PPO (which fits its value in its own epochs). ConfigError naming
    the field."""
    if not is_among(learner, LEARNERS):
        fail("learner", f"must be one of {LEARNERS}, got {learner!r}")
    if not is_among(fisher, FISHER_FORMS):
        fail("fisher", f"must be one of {FISHER_FORMS}, got {fisher!r}")
    if learner == "ppo" and value_epochs != 1:
        fail("value_epochs", "is TRPO's value fit; PPO fits its value in its own epochs")
