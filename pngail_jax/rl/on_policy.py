"""What every policy learner shares (TRPO, ``rl.trpo``; PPO, ``rl.ppo``): the static settings
of the rollout, the networks and the evaluation (``RolloutConfig``, plain data in the
config's learner part, ``pngail_jax.config.learner``, re-exported here), the observation
normaliser, the ``OnPolicyLearner`` base class (networks, auto-resetting envs, rollout,
log-probabilities, evaluation), the episode metrics of a rollout, and
``run_evaluated_blocks``, the scan of iterations and evaluations every trainer runs."""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from pngail_jax import envs
from pngail_jax.config.learner import RolloutConfig
from pngail_jax.networks import GaussianPolicy, ValueNetwork, gaussian_log_prob
from pngail_jax.rl.rollout import Transitions, collect, evaluate


@struct.dataclass
class ObservationNormalizer:
    """Running mean and variance of observations (Welford / Chan parallel update)."""

    count: jax.Array
    mean: jax.Array
    sum_squares: jax.Array

    @classmethod
    def create(cls, size: int) -> ObservationNormalizer:
        return cls(count=jnp.zeros(()), mean=jnp.zeros(size), sum_squares=jnp.zeros(size))

    def update(self, obs: jax.Array) -> ObservationNormalizer:
        obs = obs.reshape(-1, obs.shape[-1])
        batch_count = obs.shape[0]
        batch_mean = obs.mean(axis=0)
        batch_sum_squares = ((obs - batch_mean) ** 2).sum(axis=0)
        count = self.count + batch_count
        delta = batch_mean - self.mean
        return ObservationNormalizer(
            count=count,
            mean=self.mean + delta * batch_count / count,
            sum_squares=self.sum_squares
            + batch_sum_squares
            + delta**2 * self.count * batch_count / count,
        )

    def __call__(self, obs: jax.Array) -> jax.Array:
        std = jnp.sqrt(self.sum_squares / jnp.maximum(self.count, 1.0)) + 1e-8
        normalized = jnp.clip((obs - self.mean) / std, -10.0, 10.0)
        return jnp.where(self.count > 0, normalized, obs)


def episode_metrics(transitions: Transitions, rewards: jax.Array) -> dict[str, jax.Array]:
    """The mean return of the whole episodes that ended in the rollout (NaN when none did;
    a staggered first episode cut short does not count) and the mean reward the update
    learnt from."""
    finished = (transitions.done | transitions.truncated) & ~transitions.ended_early
    num_finished = finished.sum()
    return {
        "train/episode_return": jnp.where(
            num_finished > 0,
            jnp.where(finished, transitions.episode_return, 0.0).sum()
            / jnp.maximum(num_finished, 1),
            jnp.nan,
        ),
        "train/reward": rewards.mean(),
    }


class OnPolicyLearner:
    """What TRPO and PPO share for one environment and static config: the Gaussian policy and
    value networks, the auto-resetting envs, the rollout, log-probabilities and evaluation.

    A learner's state has at least ``policy_params``, ``value_params``, ``normalizer``,
    ``env_state``, ``env_steps`` and ``key``; ``LEARNED_FIELDS`` names the fields its update
    learns (what a frozen cloned policy keeps, ``adversarial``).
    """

    LEARNED_FIELDS: tuple[str, ...] = ("policy_params", "value_params", "normalizer")
    HYPERPARAMS: type  # the per-cell values its update reads

    def check_hyperparams(self, hyperparams) -> None:
        """ValueError unless ``hyperparams`` are this learner's (a cell made for the other
        learner would otherwise fail deep inside the update)."""
        if not isinstance(hyperparams, self.HYPERPARAMS):
            raise ValueError(
                f"this trainer's learner is {type(self).__name__}, which reads "
                f"{self.HYPERPARAMS.__name__}, but the cell gives "
                f"{type(hyperparams).__name__}: make the cells for the same learner "
                "(AdversarialHyperparams.create(learner=...), stack_cells(..., learner=...))"
            )

    def __init__(self, config: RolloutConfig, env: envs.Env):
        self.config = config
        self.env = env
        self.auto_env = envs.AutoReset(env)
        self.policy = GaussianPolicy(env.action_size, config.hidden_sizes)
        self.value = ValueNetwork(config.hidden_sizes)

    def reset_envs(self, key: jax.Array) -> envs.AutoResetState:
        """The ``num_envs`` parallel envs' first states (leaves [N, ...]); with
        ``stagger_starts``, each first episode cut at its own random length."""
        num_envs = self.config.num_envs
        if not self.config.stagger_starts:
            return jax.vmap(self.auto_env.reset)(jax.random.split(key, num_envs))
        reset_key, limit_key = jax.random.split(key)
        return jax.vmap(self.auto_env.staggered_reset)(
            jax.random.split(reset_key, num_envs), jax.random.split(limit_key, num_envs)
        )

    def rollout(self, state):
        """``unroll_length`` steps of the ``num_envs`` envs with the current stochastic policy:
        (state with the envs, key and step count moved on, Transitions float[T, N, ...])."""
        key, rollout_key = jax.random.split(state.key)
        env_state, transitions = collect(
            self.auto_env,
            self.policy,
            state.policy_params,
            state.normalizer,
            state.env_state,
            self.config.unroll_length,
            rollout_key,
        )
        state = state.replace(
            env_state=env_state, key=key, env_steps=state.env_steps + self.config.batch_size
        )
        return state, transitions

    def log_prob(self, state, obs: jax.Array, action: jax.Array) -> jax.Array:
        """log pi(action | obs) of the current policy: obs float[..., O], action float[..., A]."""
        mean, log_std = self.policy.apply(state.policy_params, state.normalizer(obs))
        return gaussian_log_prob(mean, log_std, action)

    def evaluate(self, state, keys: jax.Array) -> jax.Array:
        return evaluate(self.env, self.policy, state.policy_params, state.normalizer, keys)

    def updated_normalizer(self, state, transitions: Transitions) -> ObservationNormalizer:
        """The observation normaliser after this rollout (unchanged when normalisation is
        off)."""
        if self.config.normalize_observations:
            return state.normalizer.update(transitions.obs)
        return state.normalizer


def run_evaluated_blocks(
    learner: OnPolicyLearner, iteration, state, learner_state_of, eval_keys, num_blocks
):
    """``num_blocks`` (static) scans of ``learner.config.eval_every`` iterations, each followed by
    a deterministic evaluation of ``learner_state_of(state)`` on ``eval_keys``.

    ``iteration(state) -> (state, metrics)``; returns the final state and the metrics flattened
    to float[num_blocks * eval_every], with ``eval/return`` NaN except at each block's end.
    """
    eval_every = learner.config.eval_every

    def block(state, _):
        state, metrics = jax.lax.scan(lambda s, _: iteration(s), state, None, length=eval_every)
        eval_return = learner.evaluate(learner_state_of(state), eval_keys)
        metrics["eval/return"] = jnp.full((eval_every,), jnp.nan).at[-1].set(eval_return)
        return state, metrics

    state, metrics = jax.lax.scan(block, state, None, length=num_blocks)
    return state, jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), metrics)
