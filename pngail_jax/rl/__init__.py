"""Policy learners in pure JAX: TRPO (the paper's: conjugate gradient, Fisher products, line
search) and PPO, on shared rollouts, GAE, networks and evaluation."""

from pngail_jax.rl.learners import LEARNERS, LearnerConfig, learner_hyperparams, make_learner
from pngail_jax.rl.on_policy import RolloutConfig
from pngail_jax.rl.policy_trainer import PolicyTrainer, PolicyTrainState
from pngail_jax.rl.ppo import PPO, PPOConfig, PPOHyperparams, PPOState
from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams, TRPOState

__all__ = [
    "LEARNERS",
    "LearnerConfig",
    "PPO",
    "PPOConfig",
    "PPOHyperparams",
    "PPOState",
    "RolloutConfig",
    "TRPO",
    "TRPOConfig",
    "TRPOHyperparams",
    "TRPOState",
    "PolicyTrainState",
    "PolicyTrainer",
    "learner_hyperparams",
    "make_learner",
]

# Old names of PolicyTrainer and PolicyTrainState (they run PPO too), kept until 0.3.
_RENAMED = {"TRPOTrainer": "PolicyTrainer", "TRPOTrainState": "PolicyTrainState"}


def __getattr__(name: str):
    if name in _RENAMED:
        import warnings

        warnings.warn(
            f"pngail_jax.rl.{name} is pngail_jax.rl.{_RENAMED[name]} (it runs PPO too); the old "
            "name goes in 0.3",
            DeprecationWarning,
            stacklevel=2,
        )
        return globals()[_RENAMED[name]]
    raise AttributeError(f"module 'pngail_jax.rl' has no attribute {name!r}")
