"""PPO in pure JAX, beside TRPO: the same rollout, GAE, networks and evaluation.

One update (``PPO.update``) on a rollout of ``num_envs x unroll_length`` steps and its rewards:

1. GAE(gamma, lambda) advantages and value targets ``A + V(s)`` from one pass (the value
   network before the update);
2. ``num_epochs`` passes over the batch, each a fresh permutation cut into ``num_minibatches``
   minibatches; on each, one Adam step of the policy and value networks together on

       L = -mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A))
           - entropy_coef H(pi) + value_coef * 0.5 mean(max((V - R)^2, (V_clip - R)^2)),

   with rho = pi(a|s) / pi_old(a|s), A standardised within the minibatch, and
   ``V_clip = V_old + clip(V - V_old, -eps, eps)`` (the clipped value loss; the plain squared
   error when ``clip_value_loss`` is off); the gradient clipped to a global norm of
   ``max_grad_norm``; the learning rate annealed linearly to 0 over the run.

The defaults are CleanRL's ``ppo_continuous_action.py`` (its MuJoCo settings: gamma 0.99,
lambda 0.95, clip 0.2, 10 epochs, 32 minibatches, Adam 3e-4 with eps 1e-5 annealed, value
coefficient 0.5, no entropy bonus, gradient norm 0.5, clipped value loss). Where this PPO
departs from it (docs/ppo.md): the networks and the rollout shape are the task's (TRPO's
tanh 100 x 100 networks, ``num_envs x unroll_length`` from the settings table, where CleanRL
has 64 x 64 with orthogonal initialisation and one env of 2,048 steps), observation
normalisation follows ``RolloutConfig.normalize_observations``, and the reward normalisation's
statistics are updated once per rollout (CleanRL's wrapper updates them every step).
"""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import optax
from flax import struct

from pngail_jax import envs
from pngail_jax.config.learner import PPOConfig, check_hyperparam
from pngail_jax.networks import gaussian_entropy, gaussian_kl, gaussian_log_prob
from pngail_jax.rl.gae import generalized_advantages
from pngail_jax.rl.on_policy import (
    ObservationNormalizer,
    OnPolicyLearner,
    RolloutConfig,
    episode_metrics,
)
from pngail_jax.rl.rollout import Transitions, rollout_metrics


@struct.dataclass
class PPOHyperparams:
    """Per-run values (pytree leaves, so a grid can vmap over them)."""

    gamma: jax.Array
    lam: jax.Array
    clip_eps: jax.Array
    learning_rate: jax.Array
    entropy_coef: jax.Array
    value_coef: jax.Array
    max_grad_norm: jax.Array
    bootstrap_truncation: jax.Array  # bool[]: False treats truncation as terminal

    @classmethod
    def create(
        cls,
        gamma=0.99,
        lam=0.95,
        clip_eps=0.2,
        learning_rate=3e-4,
        entropy_coef=0.0,
        value_coef=0.5,
        max_grad_norm=0.5,
        bootstrap_truncation=True,
    ) -> PPOHyperparams:
        positive = dict(
            gamma=gamma, lam=lam, clip_eps=clip_eps, learning_rate=learning_rate,
            value_coef=value_coef, max_grad_norm=max_grad_norm,
        )  # fmt: skip
        floats = {**positive, "entropy_coef": entropy_coef}
        for name, value in floats.items():
            check_hyperparam("ppo", name, value)
        return cls(
            **{k: jnp.asarray(v, jnp.float32) for k, v in floats.items()},
            bootstrap_truncation=jnp.asarray(bootstrap_truncation, bool),
        )


@struct.dataclass
class PPOState:
    """A PPO learner's state: the fields of ``TRPOState`` that agree (so rollouts, policy
    export and checkpoints read both the same way) and one Adam state over both networks."""

    policy_params: dict
    value_params: dict
    optimizer_state: optax.OptState
    normalizer: ObservationNormalizer
    env_state: envs.AutoResetState
    env_steps: jax.Array
    key: jax.Array
    # The reward normalisation's statistics of the discounted return (one entry), and each
    # env's discounted return so far in its episode, float[N].
    return_normalizer: ObservationNormalizer
    discounted_return: jax.Array


class PPOBatch(struct.PyTreeNode):
    """The flattened rollout an update trains on (each float[B, ...])."""

    obs: jax.Array  # normalised
    actions: jax.Array
    old_log_prob: jax.Array
    old_values: jax.Array
    advantages: jax.Array  # GAE(lambda), not standardised
    value_targets: jax.Array  # advantages + old values


def clipped_surrogate_loss(log_prob, old_log_prob, advantages, clip_eps):
    """PPO's policy loss ``-mean(min(rho A, clip(rho, 1 - eps, 1 + eps) A))`` with
    ``rho = exp(log_prob - old_log_prob)``, and the share of rows where the clip is active:
    (float[], float[])."""
    ratio = jnp.exp(log_prob - old_log_prob)
    unclipped = ratio * advantages
    clipped = jnp.clip(ratio, 1 - clip_eps, 1 + clip_eps) * advantages
    clip_fraction = jnp.mean((jnp.abs(ratio - 1) > clip_eps).astype(ratio.dtype))
    return -jnp.mean(jnp.minimum(unclipped, clipped)), clip_fraction


def value_loss(values, old_values, targets, clip_eps, clip: bool):
    """``0.5 mean(max((V - R)^2, (V_clip - R)^2))`` with ``V_clip = V_old + clip(V - V_old,
    -eps, eps)`` when ``clip``, else ``0.5 mean((V - R)^2)``: float[]."""
    squared = (values - targets) ** 2
    if not clip:
        return 0.5 * jnp.mean(squared)
    clipped_values = old_values + jnp.clip(values - old_values, -clip_eps, clip_eps)
    return 0.5 * jnp.mean(jnp.maximum(squared, (clipped_values - targets) ** 2))


def standardized(x: jax.Array) -> jax.Array:
    return (x - x.mean()) / (x.std() + 1e-8)


class PPO(OnPolicyLearner):
    """The pieces of a PPO run for one environment and static configs: ``init``,
    ``rollout``, ``update`` and ``evaluate``, pure, with the same signatures as ``TRPO``'s, so
    a trainer runs either."""

    LEARNED_FIELDS = (
        "policy_params", "value_params", "optimizer_state", "normalizer", "return_normalizer",
    )  # fmt: skip
    HYPERPARAMS = PPOHyperparams

    def __init__(self, config: RolloutConfig, env: envs.Env, ppo: PPOConfig | None = None):
        ppo = PPOConfig() if ppo is None else ppo
        ppo.check_batch(config)
        super().__init__(config, env)
        self.ppo = ppo
        self.optimizer = optax.scale_by_adam(eps=1e-5)

    def init(self, key: jax.Array) -> PPOState:
        policy_key, value_key, env_key, carry_key = jax.random.split(key, 4)
        dummy_obs = jnp.zeros((self.env.observation_size,))
        params = {
            "policy": self.policy.init(policy_key, dummy_obs),
            "value": self.value.init(value_key, dummy_obs),
        }
        return PPOState(
            policy_params=params["policy"],
            value_params=params["value"],
            optimizer_state=self.optimizer.init(params),
            normalizer=ObservationNormalizer.create(self.env.observation_size),
            env_state=self.reset_envs(env_key),
            env_steps=jnp.zeros((), jnp.int32),
            key=carry_key,
            return_normalizer=ObservationNormalizer.create(1),
            discounted_return=jnp.zeros(self.config.num_envs),
        )

    def normalized_rewards(self, hyperparams, state, transitions, rewards):
        """``rewards`` float[T, N] divided by the running standard deviation of the discounted
        return (updated with this rollout's) and clipped to [-10, 10], with the new statistics
        and each env's discounted return at the rollout's end; unchanged when
        ``normalize_rewards`` is off."""
        if not self.ppo.normalize_rewards:
            return rewards, state.return_normalizer, state.discounted_return
        finished = transitions.done | transitions.truncated

        def accumulate(running, step):
            reward, ended = step
            running = running * hyperparams.gamma + reward
            return jnp.where(ended, 0.0, running), running

        last, returns = jax.lax.scan(accumulate, state.discounted_return, (rewards, finished))
        statistics = state.return_normalizer.update(returns[..., None])
        std = jnp.sqrt(statistics.sum_squares[0] / jnp.maximum(statistics.count, 1.0))
        return jnp.clip(rewards / (std + 1e-8), -10.0, 10.0), statistics, last

    def learning_rate(self, hyperparams: PPOHyperparams, state: PPOState) -> jax.Array:
        """This update's learning rate: annealed linearly from ``learning_rate`` at the first
        iteration to ``learning_rate / num_iterations`` at the last (CleanRL's schedule; the
        rollout has already counted this iteration's steps)."""
        if not self.ppo.anneal_learning_rate:
            return hyperparams.learning_rate
        config = self.config
        done = state.env_steps // config.batch_size - 1  # iterations before this one
        remaining = 1.0 - done.astype(jnp.float32) / config.num_iterations
        return hyperparams.learning_rate * jnp.clip(remaining, 0.0, 1.0)

    def batch(
        self, hyperparams, state, transitions, rewards
    ) -> tuple[ObservationNormalizer, PPOBatch]:
        """The observation normaliser after this rollout and the flattened batch with GAE
        advantages and value targets (one pass, the value network before the update)."""
        normalizer = self.updated_normalizer(state, transitions)
        obs = normalizer(transitions.obs)
        values = self.value.apply(state.value_params, obs)
        next_values = self.value.apply(state.value_params, normalizer(transitions.final_obs))
        advantages, targets = generalized_advantages(
            rewards, values, next_values, transitions.done, transitions.truncated,
            hyperparams.gamma, hyperparams.lam, hyperparams.bootstrap_truncation,
            self.config.gae_form,
        )  # fmt: skip
        mean, log_std = self.policy.apply(state.policy_params, obs)
        old_log_prob = gaussian_log_prob(mean, log_std, transitions.action)
        size = self.config.batch_size
        flat = lambda x: x.reshape(size, *x.shape[2:])  # noqa: E731
        return normalizer, PPOBatch(
            obs=flat(obs),
            actions=flat(transitions.action),
            old_log_prob=flat(old_log_prob),
            old_values=flat(values),
            advantages=flat(advantages),
            value_targets=flat(targets),
        )

    def loss(self, hyperparams: PPOHyperparams, params: dict, batch: PPOBatch):
        """PPO's loss on one minibatch (``params``: {"policy", "value"}) and its parts."""
        mean, log_std = self.policy.apply(params["policy"], batch.obs)
        log_prob = gaussian_log_prob(mean, log_std, batch.actions)
        policy_loss, clip_fraction = clipped_surrogate_loss(
            log_prob, batch.old_log_prob, standardized(batch.advantages), hyperparams.clip_eps
        )
        values = self.value.apply(params["value"], batch.obs)
        v_loss = value_loss(
            values, batch.old_values, batch.value_targets, hyperparams.clip_eps,
            self.ppo.clip_value_loss,
        )  # fmt: skip
        entropy = gaussian_entropy(log_std)
        total = policy_loss - hyperparams.entropy_coef * entropy + hyperparams.value_coef * v_loss
        parts = {
            "ppo/policy_loss": policy_loss,
            "ppo/clip_fraction": clip_fraction,
            "value/loss": v_loss,
        }
        return total, parts

    def epochs(self, hyperparams, params, optimizer_state, batch, learning_rate, key):
        """``num_epochs`` passes over ``batch``, each a fresh permutation cut into
        ``num_minibatches`` minibatches, one clipped-gradient Adam step on each: ((params,
        optimizer state), each step's loss parts float[epochs, minibatches])."""
        config, ppo = self.config, self.ppo
        minibatch_size = config.batch_size // ppo.num_minibatches

        def minibatch_step(carry, indices):
            params, optimizer_state = carry
            minibatch = jax.tree.map(lambda x: x[indices], batch)
            grads, parts = jax.grad(lambda p: self.loss(hyperparams, p, minibatch), has_aux=True)(
                params
            )
            norm = jnp.sqrt(sum(jnp.sum(g**2) for g in jax.tree.leaves(grads)))
            scale = jnp.minimum(1.0, hyperparams.max_grad_norm / jnp.maximum(norm, 1e-12))
            grads = jax.tree.map(lambda g: g * scale, grads)
            updates, optimizer_state = self.optimizer.update(grads, optimizer_state)
            params = optax.apply_updates(
                params, jax.tree.map(lambda u: -learning_rate * u, updates)
            )
            return (params, optimizer_state), {**parts, "ppo/grad_norm": norm}

        def epoch(carry, epoch_key):
            order = jax.random.permutation(epoch_key, config.batch_size)
            order = order[: ppo.num_minibatches * minibatch_size]
            return jax.lax.scan(
                minibatch_step, carry, order.reshape(ppo.num_minibatches, minibatch_size)
            )

        return jax.lax.scan(epoch, (params, optimizer_state), jax.random.split(key, ppo.num_epochs))

    def update(
        self,
        hyperparams: PPOHyperparams,
        state: PPOState,
        transitions: Transitions,
        rewards: jax.Array,
    ) -> tuple[PPOState, dict[str, jax.Array]]:
        """``num_epochs`` epochs of minibatch Adam steps on ``rewards`` float[T, N]. Returns
        the new state and scalar metrics of the update and of the rollout it learnt from."""
        config = self.config
        chex.assert_shape(rewards, (config.unroll_length, config.num_envs))
        scaled, return_normalizer, discounted_return = self.normalized_rewards(
            hyperparams, state, transitions, rewards
        )
        normalizer, batch = self.batch(hyperparams, state, transitions, scaled)
        learning_rate = self.learning_rate(hyperparams, state)
        key, epochs_key = jax.random.split(state.key)
        params = {"policy": state.policy_params, "value": state.value_params}
        (params, optimizer_state), parts = self.epochs(
            hyperparams, params, state.optimizer_state, batch, learning_rate, epochs_key
        )
        old_mean, old_log_std = self.policy.apply(state.policy_params, batch.obs)
        new_mean, new_log_std = self.policy.apply(params["policy"], batch.obs)
        metrics = {
            **episode_metrics(transitions, rewards),
            **jax.tree.map(jnp.mean, parts),
            "ppo/kl": jnp.mean(gaussian_kl(old_mean, old_log_std, new_mean, new_log_std)),
            "ppo/entropy": gaussian_entropy(new_log_std),
            "ppo/learning_rate": learning_rate,
            **rollout_metrics(transitions, self.env),
        }
        state = state.replace(
            policy_params=params["policy"],
            value_params=params["value"],
            optimizer_state=optimizer_state,
            normalizer=normalizer,
            key=key,
            return_normalizer=return_normalizer,
            discounted_return=discounted_return,
        )
        return state, metrics
