"""Policy learners in pure JAX: TRPO (the paper's: conjugate gradient, Fisher products, line
search) and PPO, on shared rollouts, GAE, networks and evaluation."""

from pngail_jax.rl.learners import LEARNERS, learner_hyperparams, make_learner
from pngail_jax.rl.on_policy import RolloutConfig
from pngail_jax.rl.ppo import PPO, PPOConfig, PPOHyperparams, PPOState
from pngail_jax.rl.train import TRPOTrainer, TRPOTrainState
from pngail_jax.rl.trpo import TRPO, TRPOConfig, TRPOHyperparams, TRPOState

__all__ = [
    "LEARNERS",
    "PPO",
    "PPOConfig",
    "PPOHyperparams",
    "PPOState",
    "RolloutConfig",
    "TRPO",
    "TRPOConfig",
    "TRPOHyperparams",
    "TRPOState",
    "TRPOTrainState",
    "TRPOTrainer",
    "learner_hyperparams",
    "make_learner",
]
