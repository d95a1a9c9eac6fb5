"""The policy learners by name: ``"trpo"`` (the paper's, the default) and ``"ppo"``.

A learner is one static choice of a run: every cell of a grid uses the same one, so a grid
compiles into one program per learner. Its per-cell values are a hyperparameter pytree of
its own (``TRPOHyperparams`` or ``PPOHyperparams``).
"""

from __future__ import annotations

from pngail_jax import envs
from pngail_jax.config.learner import LEARNERS as LEARNERS
from pngail_jax.config.learner import LearnerConfig, check_hyperparam_names, learner_with_settings
from pngail_jax.config.learner import check_batch as check_batch
from pngail_jax.config.learner import hyperparam_names as hyperparam_names
from pngail_jax.config.learner import learner_name as check_learner  # noqa: F401  (its old name)
from pngail_jax.rl.on_policy import OnPolicyLearner, RolloutConfig
from pngail_jax.rl.ppo import PPO, PPOConfig, PPOHyperparams
from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams

HYPERPARAMS = {"trpo": TRPOHyperparams, "ppo": PPOHyperparams}


def make_learner(
    learner: LearnerConfig | str,
    config: RolloutConfig,
    env: envs.Env,
    ppo: PPOConfig | None = None,
    trpo: TRPOConfig | None = None,
) -> OnPolicyLearner:
    """The policy learner ``learner`` describes (a ``LearnerConfig``: its name and settings; a
    name alone: that learner at its defaults) for ``env``; ``config`` gives the rollout's
    shape and networks. ``ppo`` and ``trpo`` are deprecated (gone in 0.3): the settings
    passed beside a name before the learner part, each replacing ``learner``'s own."""
    part = learner_with_settings(learner, "make_learner", trpo, ppo)
    if part.name == "ppo":
        return PPO(config, env, part.ppo)
    return TRPO(config, env, part.trpo)


def learner_hyperparams(name: str, **values) -> TRPOHyperparams | PPOHyperparams:
    """Learner ``name``'s hyperparameters with ``values`` (ValueError naming a value the
    learner does not read, and which learner does)."""
    check_hyperparam_names(name, values)
    return HYPERPARAMS[name].create(**values)
