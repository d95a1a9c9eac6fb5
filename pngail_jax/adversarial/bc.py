"""Behaviour cloning, two kinds.

- The ``bc`` / ``bc-weighted`` baselines: the TRPO policy's Gaussian log-likelihood of the
  demonstrations' actions, optionally weighted per row by its confidence (``train_bc``).
- D-REX's cloned policy, which only makes D-REX's noisy rollouts: a separate deterministic
  ReLU network fitted by mean squared error, as the CAIL codebase's ``DREX.train_bc``
  (``train_deterministic_bc``).

``CloningPhase`` is the first kind's phase in the adversarial trainer.
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp

from pngail_jax.adversarial.phase import Phase, PhaseContext
from pngail_jax.fitting import fit_with_adam, squared_norm, tree_where
from pngail_jax.networks import DeterministicPolicy, gaussian_log_prob


@dataclasses.dataclass(frozen=True)
class BCConfig:
    num_steps: int = 2_000
    batch_size: int = 128
    learning_rate: float = 1e-3

    def __post_init__(self):
        for name in ("num_steps", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"BCConfig.{name} must be a positive integer, got {value!r}")


def bc_loss(mean: jax.Array, log_std: jax.Array, actions: jax.Array, weights: jax.Array):
    """-sum_i w_i log pi(a_i | s_i) / sum_i w_i, with the policy's mean float[B, A] and
    log_std float[A] on a batch of actions float[B, A] and weights float[B]."""
    chex.assert_equal_shape([mean, actions])
    log_prob = gaussian_log_prob(mean, log_std, actions)
    loss = -jnp.sum(weights * log_prob) / jnp.maximum(weights.sum(), 1e-8)
    return loss, {"bc/loss": loss}


def train_bc(config: BCConfig, policy_apply, params, observations, actions, weights, key):
    """Adam on ``bc_loss`` from ``params`` with batches drawn with probability proportional
    to ``weights`` float[N] (so weights 0 are never drawn; all equal: plain BC). Returns
    ``(params, metrics)``, metrics float[num_steps]."""
    probabilities = weights / jnp.maximum(weights.sum(), 1e-8)

    def loss_fn(params, key):
        rows = jax.random.choice(key, observations.shape[0], (config.batch_size,), p=probabilities)
        mean, log_std = policy_apply(params, observations[rows])
        return bc_loss(mean, log_std, actions[rows], jnp.ones(rows.shape))

    keys = jax.random.split(key, config.num_steps)
    return fit_with_adam(loss_fn, params, config.learning_rate, keys)


@dataclasses.dataclass(frozen=True)
class DeterministicBCConfig:
    """D-REX's behaviour cloning, with the CAIL codebase's values (``cail/algo/drex.py``):
    a 256x256x256 ReLU network with a tanh output scaled to the action bounds, Adam at 1e-3 on
    MSE + 1e-3 ||theta||^2, 50,000 steps of 128 rows drawn uniformly from every
    demonstration."""

    num_steps: int = 50_000
    batch_size: int = 128
    learning_rate: float = 1e-3
    l2_coef: float = 1e-3
    hidden_sizes: tuple[int, ...] = (256, 256, 256)

    def __post_init__(self):
        for name in ("num_steps", "batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(
                    f"DeterministicBCConfig.{name} must be a positive integer, got {value!r}"
                )
        if not self.l2_coef >= 0:
            raise ValueError(f"DeterministicBCConfig.l2_coef must be >= 0, got {self.l2_coef!r}")


def deterministic_bc_loss(predicted: jax.Array, targets: jax.Array, params, l2_coef):
    """mean((predicted - targets)^2) + l2_coef ||params||^2, the mean over every element
    (torch's ``MSELoss``), on actions float[B, A] in the policy's [-1, 1] units.

    Returns ``(loss, metrics)``.
    """
    chex.assert_equal_shape([predicted, targets])
    mse = jnp.mean(jnp.square(predicted - targets))
    penalty = l2_coef * squared_norm(params)
    return mse + penalty, {"bc/mse": mse, "bc/l2": penalty}


def cloned_actions(config: DeterministicBCConfig, params, observations, low, high):
    """The cloned policy's actions float[..., A] in the environment's units: its tanh output
    in [-1, 1] mapped linearly onto [low, high] (float[A] each), as the CAIL codebase's
    ``NormalizedEnv`` scales its actions."""
    unit = DeterministicPolicy(low.shape[-1], config.hidden_sizes).apply(params, observations)
    return low + (unit + 1) * (high - low) / 2


def train_deterministic_bc(
    config: DeterministicBCConfig, observations, actions, low, high, key: jax.Array
):
    """Fits ``DeterministicPolicy`` to ``actions`` float[N, A] (within [low, high]) on
    ``observations`` float[N, O]: Adam on ``deterministic_bc_loss`` in the policy's [-1, 1]
    units (the CAIL codebase's demonstrations are stored in those units), batches drawn
    uniformly with replacement. Returns ``(params, metrics)``, metrics float[num_steps]."""
    policy = DeterministicPolicy(actions.shape[-1], config.hidden_sizes)
    init_key, train_key = jax.random.split(key)
    params = policy.init(init_key, observations[0])
    targets = 2 * (actions - low) / (high - low) - 1

    def loss_fn(params, key):
        rows = jax.random.randint(key, (config.batch_size,), 0, observations.shape[0])
        predicted = policy.apply(params, observations[rows])
        return deterministic_bc_loss(predicted, targets[rows], params, config.l2_coef)

    keys = jax.random.split(train_key, config.num_steps)
    return fit_with_adam(loss_fn, params, config.learning_rate, keys)


class CloningPhase(Phase):
    """Behaviour cloning in the adversarial trainer: the learner's policy cloned from the
    split's rows (each weighted by 1 + ``spec.bc_weighted_coef`` (r - 1)) starts the cells
    with ``spec.bc_init_coef`` 1; in cells with ``spec.policy_update_coef`` 0 no RL moves it."""

    names = ("bc",)

    def __init__(self, config: BCConfig):
        self.config = config

    def init(self, context: PhaseContext, spec, inputs, confidence, learner_state, keys, ranked):
        size, policy = context.env.observation_size, context.learner.policy
        normalizer = learner_state.normalizer
        weights = 1 + spec.bc_weighted_coef * (confidence - 1)
        bc_params, _ = train_bc(
            self.config,
            lambda params, obs: policy.apply(params, normalizer(obs)),
            learner_state.policy_params,
            inputs[:, :size],
            inputs[:, size:],
            weights,
            keys.bc,
        )
        policy_params = tree_where(spec.bc_init_coef > 0, bc_params, learner_state.policy_params)
        return {}, learner_state.replace(policy_params=policy_params)

    def after_update(self, context: PhaseContext, spec, before, updated):
        """A cloned policy that no RL moves (``policy_update_coef`` 0) stays as it was: the
        learner's learned fields from ``before``, the rest (counters, keys, the envs) from
        ``updated``."""
        frozen = spec.policy_update_coef == 0
        return updated.replace(
            **{
                name: tree_where(frozen, getattr(before, name), getattr(updated, name))
                for name in context.learner.LEARNED_FIELDS
            }
        )
