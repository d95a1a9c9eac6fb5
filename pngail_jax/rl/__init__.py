"""TRPO in pure JAX: rollouts, GAE, conjugate gradient, Fisher products, line search."""

from pngail_jax.rl.train import (
    TRPO,
    TRPOConfig,
    TRPOHyperparams,
    TRPOState,
    TRPOTrainer,
    TRPOTrainState,
)

__all__ = ["TRPO", "TRPOConfig", "TRPOHyperparams", "TRPOState", "TRPOTrainState", "TRPOTrainer"]
