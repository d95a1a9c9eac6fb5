"""The grid part of a run's config, as plain data: which fields a grid axis may vary per cell
(``GRID_AXES``) and which it may not, because they shape the one compiled program every cell
shares (``STATIC_FIELDS``), and the check of a config's ``grid_axes``. Imports no JAX:
``pngail_jax.grid`` stacks cells over these axes, and tests/test_grid.py holds the tables to
the trainers' own fields (``AdversarialHyperparams``, ``MethodSpec``, the static configs)."""

from __future__ import annotations

import math

from pngail_jax.config.validation import ConfigError, fail, float_axis

# Per-cell values a grid axis may vary besides label ratio and noise (their own axes): the
# pytree leaves of AdversarialHyperparams (the learner's included: TRPO's or PPO's, each only
# on a run of its learner) and of MethodSpec. Everything else (network widths, rollout shape,
# step counts, the learner itself) fixes the compiled program's shapes or loops, which every
# cell shares.
HYPERPARAM_AXES = (
    "discriminator_learning_rate", "gamma", "lam", "max_kl", "damping", "value_learning_rate",
    "clip_eps", "learning_rate", "entropy_coef", "value_coef", "max_grad_norm",
)  # fmt: skip
# MethodSpec's fields (pngail_jax.adversarial.methods), in its order.
METHOD_AXES = (
    "agent_coef", "gail_coef", "importance_weighted_coef", "pn_coef", "wgail_coef",
    "icgail_coef", "class_prior_floor", "classifier_coef", "bsc_coef", "bsc_eps",
    "adversarial_reward_coef", "policy_update_coef", "bc_init_coef", "bc_weighted_coef",
    "ranking_reward_coef", "noise_rankings_coef", "firl_coef", "firl_fkl_coef",
    "firl_rkl_coef", "firl_js_coef", "cail_coef", "cail_learning_rate", "pu_coef", "pu_prior",
    "pu_agent_coef", "pu_agent_prior", "pn_negative_coef", "pn_balanced_coef",
    "logit_reward_coef", "gradient_penalty_coef",
)  # fmt: skip
GRID_AXES = HYPERPARAM_AXES + METHOD_AXES
# The fields a grid axis cannot vary, with a reason (they shape the compiled program): those
# of RunSettings, RolloutConfig, TRPOConfig, ClassifierConfig and PPOConfig, and the run's
# own counts and widths.
STATIC_FIELDS = frozenset(
    (
        "anneal_learning_rate", "chunk_iterations", "clip_value_loss",
        "discriminator_hidden_sizes", "dropout_rate", "eval_every", "fisher", "fisher_subsample",
        "gae_form", "hidden_sizes", "iterations", "labelled_batch_size", "learner",
        "learning_rate", "ls_iterations", "max_unlabelled_batch_size", "normalize_observations",
        "normalize_rewards", "num_backtracks", "num_cg_iterations", "num_demos", "num_envs",
        "num_epochs", "num_eval_episodes", "num_iterations", "num_minibatches", "num_steps",
        "num_value_epochs", "num_value_minibatches", "physics", "seeds", "solver_iterations",
        "stagger_starts", "unlabelled_batch_size", "unroll_length",
    )
)  # fmt: skip


def check_grid_axes(axes) -> tuple[tuple[str, tuple[float, ...]], ...]:
    """``((field, (value, ...)), ...)`` checked: per-cell fields (``GRID_AXES``; a static one
    is refused saying why), each once, with distinct finite values."""
    if not isinstance(axes, list | tuple) or not all(
        isinstance(axis, list | tuple) and len(axis) == 2 for axis in axes
    ):
        fail("grid_axes", f"must be (field, values) pairs, got {axes!r}")
    fields = [axis[0] for axis in axes]
    for field in fields:
        if field in ("label_ratio", "noise_std"):
            fail("grid_axes", f": {field} has its own axis ({field}s)")
        if not isinstance(field, str) or field not in GRID_AXES:
            static = isinstance(field, str) and field in STATIC_FIELDS
            why = (
                "is static: it fixes the shapes or loop counts of the one compiled program that "
                "every cell shares; set it with its own option"
                if static
                else "is not a per-cell field"
            )
            fail("grid_axes", f": {field!r} {why}; axes: {', '.join(GRID_AXES)}")
    if len(set(fields)) != len(fields):
        fail("grid_axes", f": an axis is given twice, got {fields}")
    checked = []
    for field, values in axes:
        values = tuple(values) if isinstance(values, list | tuple) else (values,)
        try:
            values = float_axis(field, values, "be finite numbers", math.isfinite)
        except ConfigError as error:
            fail("grid_axes", f": {field} values {error.reason}")
        labels = [f"{value:g}" for value in values]  # a setting's label names its value
        if len(set(labels)) != len(labels):
            fail("grid_axes", f": {field} values {list(values)} are not distinct to 6 digits")
        checked.append((field, values))
    return tuple(checked)
