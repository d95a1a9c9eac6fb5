"""TRPO in pure JAX, and ``TRPOTrainer``: TRPO on a fixed reward as one pure program.

Static configuration (shapes, iteration counts, which Fisher product) lives in the frozen
``TRPOConfig``; everything a grid may vary (discount, KL bound, learning rate, whether to
bootstrap through truncation) is a ``TRPOHyperparams`` pytree, so
``jax.jit(jax.vmap(TRPOTrainer(config, env).train))(stacked_hyperparams, keys)`` trains many
runs in one program.
Defaults are the paper's and the reference code's (``docs/trpo.md``), except
that GAE bootstraps the value through time-limit truncation (``bootstrap_truncation``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Literal, NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.flatten_util import ravel_pytree

from pngail_jax import envs
from pngail_jax.networks import (
    GaussianPolicy,
    ValueNetwork,
    gaussian_entropy,
    gaussian_kl,
    gaussian_log_prob,
)
from pngail_jax.rl.gae import GAEForm, generalized_advantages
from pngail_jax.rl.rollout import Transitions, collect, evaluate, rollout_metrics
from pngail_jax.rl.trpo import hessian_vector_product, natural_gradient_step

RewardFunction = Callable[[Transitions], jax.Array]


@dataclasses.dataclass(frozen=True)
class TRPOConfig:
    """Shape-giving, static settings. ``num_envs * unroll_length`` steps per iteration."""

    num_envs: int = 25
    unroll_length: int = 200
    num_iterations: int = 100
    eval_every: int = 10
    num_eval_episodes: int = 32
    hidden_sizes: tuple[int, ...] = (100, 100)
    num_value_minibatches: int = 30
    num_cg_iterations: int = 10
    num_backtracks: int = 10
    normalize_observations: bool = False
    # "hessian": Hessian of the mean KL times v, the reference's form (second-order autodiff).
    # "gauss_newton": J^T M J v for the Gaussian policy, the same matrix at the current
    # parameters, from one jvp and one vjp, and faster: the default everywhere (library,
    # sweep, train_rl), so that Python and the command line run the same program.
    fisher: Literal["hessian", "gauss_newton"] = "gauss_newton"
    # Fisher products on every k-th time step of every env (OpenAI baselines uses every 5th
    # sample); 1 = all.
    fisher_subsample: int = 1
    # GAE as a T-step scan ("sequential") or a log-depth tree ("associative"): the same
    # numbers up to float rounding (tests/test_gae.py); which is faster depends on the device.
    gae_form: GAEForm = "sequential"
    # Each env's first episode truncated at a random length (envs.AutoReset.staggered_reset),
    # so that the envs of a task that never terminates do not stay in step.
    stagger_starts: bool = False

    def __post_init__(self):
        for name in (
            "num_envs",
            "unroll_length",
            "num_iterations",
            "eval_every",
            "num_eval_episodes",
            "num_value_minibatches",
            "num_cg_iterations",
            "num_backtracks",
            "fisher_subsample",
        ):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"TRPOConfig.{name} must be a positive integer, got {value!r}")
        if self.num_iterations % self.eval_every:
            raise ValueError(
                f"TRPOConfig.num_iterations ({self.num_iterations}) must be a "
                f"multiple of eval_every ({self.eval_every})"
            )
        if not isinstance(self.stagger_starts, bool):
            raise ValueError(
                f"TRPOConfig.stagger_starts must be True or False, got {self.stagger_starts!r}"
            )
        if self.fisher not in ("hessian", "gauss_newton"):
            raise ValueError(
                f"TRPOConfig.fisher must be 'hessian' or 'gauss_newton', got {self.fisher!r}"
            )
        if self.gae_form not in ("sequential", "associative"):
            raise ValueError(
                f"TRPOConfig.gae_form must be 'sequential' or 'associative', got {self.gae_form!r}"
            )
        if self.batch_size < self.num_value_minibatches:
            raise ValueError(
                f"samples per iteration (num_envs x unroll_length = {self.num_envs} x "
                f"{self.unroll_length} = {self.batch_size}) must be at least the "
                f"{self.num_value_minibatches} value minibatches"
            )

    @property
    def batch_size(self) -> int:
        return self.num_envs * self.unroll_length

    @property
    def num_evaluations(self) -> int:
        return self.num_iterations // self.eval_every


@struct.dataclass
class TRPOHyperparams:
    """Per-run values (pytree leaves, so a grid can vmap over them)."""

    gamma: jax.Array
    lam: jax.Array
    max_kl: jax.Array
    damping: jax.Array
    value_learning_rate: jax.Array
    bootstrap_truncation: jax.Array  # bool[]: False treats truncation as terminal (reference)

    @classmethod
    def create(
        cls,
        gamma=0.995,
        lam=0.97,
        max_kl=0.01,
        damping=0.1,
        value_learning_rate=3e-4,
        bootstrap_truncation=True,
    ) -> TRPOHyperparams:
        floats = dict(
            gamma=gamma,
            lam=lam,
            max_kl=max_kl,
            damping=damping,
            value_learning_rate=value_learning_rate,
        )
        for name, value in floats.items():
            if not (value > 0) or (name in ("gamma", "lam") and value > 1):
                raise ValueError(f"TRPOHyperparams.{name} out of range: {value!r}")
        return cls(
            **{k: jnp.asarray(v, jnp.float32) for k, v in floats.items()},
            bootstrap_truncation=jnp.asarray(bootstrap_truncation, bool),
        )


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


class PolicyObjective(NamedTuple):
    """What TRPO's natural-gradient step works on (``TRPO.policy_objective``): the flat
    parameters and their unravel function, the surrogate loss and mean KL as functions of
    flat parameters, the damped Fisher-vector product, and the old policy's outputs."""

    flat_params: jax.Array
    unravel: Callable
    surrogate_loss: Callable[[jax.Array], jax.Array]
    mean_kl: Callable[[jax.Array], jax.Array]
    fisher_vector_product: Callable[[jax.Array], jax.Array]
    old_mean: jax.Array
    old_log_std: jax.Array


class LearningTargets(NamedTuple):
    """What ``TRPO.advantages_and_targets`` gives the value and policy steps."""

    normalizer: ObservationNormalizer  # updated on this rollout when normalisation is on
    obs: jax.Array  # float[T, N, O], normalised
    advantages: jax.Array  # float[T, N], standardised
    value_targets: jax.Array  # float[T, N]


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


@struct.dataclass
class TRPOState:
    policy_params: dict
    value_params: dict
    value_optimizer_state: optax.OptState
    normalizer: ObservationNormalizer
    env_state: envs.AutoResetState
    env_steps: jax.Array
    key: jax.Array


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

    def __init__(self, config: TRPOConfig, env: envs.Env):
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


class TRPO(OnPolicyLearner):
    """The pieces of a TRPO run for one environment and static config.

    ``init``, ``rollout``, ``update`` and ``evaluate`` are pure; an adversarial trainer calls
    ``rollout``, computes its own rewards and calls ``update`` with them.
    """

    LEARNED_FIELDS = ("policy_params", "value_params", "value_optimizer_state", "normalizer")
    HYPERPARAMS = TRPOHyperparams

    def __init__(self, config: TRPOConfig, env: envs.Env):
        super().__init__(config, env)
        self.value_optimizer = optax.scale_by_adam()

    def init(self, key: jax.Array) -> TRPOState:
        policy_key, value_key, env_key, carry_key = jax.random.split(key, 4)
        dummy_obs = jnp.zeros((self.env.observation_size,))
        value_params = self.value.init(value_key, dummy_obs)
        env_state = self.reset_envs(env_key)
        return TRPOState(
            policy_params=self.policy.init(policy_key, dummy_obs),
            value_params=value_params,
            value_optimizer_state=self.value_optimizer.init(value_params),
            normalizer=ObservationNormalizer.create(self.env.observation_size),
            env_state=env_state,
            env_steps=jnp.zeros((), jnp.int32),
            key=carry_key,
        )

    def update(
        self,
        hyperparams: TRPOHyperparams,
        state: TRPOState,
        transitions: Transitions,
        rewards: jax.Array,
    ) -> tuple[TRPOState, dict[str, jax.Array]]:
        """Value regression then one natural-gradient policy step, on ``rewards`` float[T, N].

        Returns the new state and scalar metrics of the step and of the rollout it learnt
        from (``rollout_metrics``: every trainer's metrics carry them).
        """
        config = self.config
        chex.assert_shape(rewards, (config.unroll_length, config.num_envs))
        targets = self.advantages_and_targets(hyperparams, state, transitions, rewards)
        flat = lambda x: x.reshape(config.batch_size, *x.shape[2:])  # noqa: E731
        key, value_key = jax.random.split(state.key)
        value_params, value_optimizer_state, value_loss = self.fit_value(
            hyperparams, state, flat(targets.obs), flat(targets.value_targets), value_key
        )
        policy_params, policy_metrics = self.policy_step(
            hyperparams,
            state.policy_params,
            flat(targets.obs),
            flat(transitions.action),
            flat(transitions.log_prob),
            flat(targets.advantages),
        )
        metrics = {
            **episode_metrics(transitions, rewards),
            "value/loss": value_loss,
            **policy_metrics,
            **rollout_metrics(transitions, self.env),
        }
        state = state.replace(
            policy_params=policy_params,
            value_params=value_params,
            value_optimizer_state=value_optimizer_state,
            normalizer=targets.normalizer,
            key=key,
        )
        return state, metrics

    def advantages_and_targets(
        self, hyperparams: TRPOHyperparams, state: TRPOState, transitions, rewards
    ) -> LearningTargets:
        """The update's first step: the observation normaliser updated (when it is on), the
        normalised observations, and from one GAE pass both the policy's standardised
        advantages (lambda) and the value targets, bootstrapped discounted returns (lambda =
        1) as the reference's; each float[T, N] (observations float[T, N, O])."""
        config = self.config
        normalizer = self.updated_normalizer(state, transitions)
        obs = normalizer(transitions.obs)
        values = self.value.apply(state.value_params, obs)
        next_values = self.value.apply(state.value_params, normalizer(transitions.final_obs))
        both_advantages, both_targets = generalized_advantages(
            rewards,
            values,
            next_values,
            transitions.done,
            transitions.truncated,
            hyperparams.gamma,
            jnp.stack([hyperparams.lam, jnp.ones_like(hyperparams.lam)]),
            hyperparams.bootstrap_truncation,
            config.gae_form,
        )
        advantages, targets = both_advantages[0], both_targets[1]
        advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        return LearningTargets(normalizer, obs, advantages, targets)

    def fit_value(self, hyperparams, state, obs, targets, key):
        """The update's value step: Adam over one permutation of the flattened batch (obs
        float[B, O], targets float[B]) in ``num_value_minibatches`` steps. Returns the value
        parameters, their optimiser state and the mean loss."""
        num_minibatches = self.config.num_value_minibatches
        minibatch_size = self.config.batch_size // num_minibatches
        order = jax.random.permutation(key, self.config.batch_size)
        order = order[: num_minibatches * minibatch_size].reshape(num_minibatches, minibatch_size)

        def loss_fn(params, indices):
            prediction = self.value.apply(params, obs[indices])
            return jnp.mean((prediction - targets[indices]) ** 2)

        def body(carry, indices):
            params, optimizer_state = carry
            loss, grads = jax.value_and_grad(loss_fn)(params, indices)
            updates, optimizer_state = self.value_optimizer.update(grads, optimizer_state)
            params = optax.apply_updates(
                params, jax.tree.map(lambda u: -hyperparams.value_learning_rate * u, updates)
            )
            return (params, optimizer_state), loss

        (params, optimizer_state), losses = jax.lax.scan(
            body, (state.value_params, state.value_optimizer_state), order
        )
        return params, optimizer_state, losses.mean()

    def policy_objective(
        self, hyperparams, policy_params, obs, actions, old_log_prob, advantages
    ) -> PolicyObjective:
        """The natural-gradient step's problem at ``policy_params`` on a flattened batch
        (obs float[B, O], actions float[B, A], old_log_prob and advantages float[B])."""
        flat_params, unravel = ravel_pytree(policy_params)
        old_mean, old_log_std = jax.lax.stop_gradient(self.policy.apply(policy_params, obs))
        fisher_rows = fisher_sample_indices(self.config)
        fisher_obs, fisher_old_mean = obs[fisher_rows], old_mean[fisher_rows]

        def surrogate_loss(flat):
            mean, log_std = self.policy.apply(unravel(flat), obs)
            ratio = jnp.exp(gaussian_log_prob(mean, log_std, actions) - old_log_prob)
            return -jnp.mean(advantages * ratio)

        def mean_kl(flat):
            mean, log_std = self.policy.apply(unravel(flat), fisher_obs)
            return jnp.mean(gaussian_kl(fisher_old_mean, old_log_std, mean, log_std))

        if self.config.fisher == "gauss_newton":
            fisher_vector_product = gauss_newton_fisher_product(
                self.policy, unravel, flat_params, fisher_obs, hyperparams.damping
            )
        else:
            fisher_vector_product = hessian_vector_product(
                mean_kl, flat_params, hyperparams.damping
            )
        return PolicyObjective(
            flat_params=flat_params,
            unravel=unravel,
            surrogate_loss=surrogate_loss,
            mean_kl=mean_kl,
            fisher_vector_product=fisher_vector_product,
            old_mean=old_mean,
            old_log_std=old_log_std,
        )

    def policy_step(self, hyperparams, policy_params, obs, actions, old_log_prob, advantages):
        """The update's policy step: one natural-gradient step (conjugate gradient, then a
        backtracking line search within ``max_kl``) on a flattened batch, with its metrics."""
        objective = self.policy_objective(
            hyperparams, policy_params, obs, actions, old_log_prob, advantages
        )
        new_flat, metrics = natural_gradient_step(
            objective.surrogate_loss,
            objective.mean_kl,
            objective.flat_params,
            hyperparams.max_kl,
            hyperparams.damping,
            self.config.num_cg_iterations,
            self.config.num_backtracks,
            objective.fisher_vector_product,
        )
        new_params = objective.unravel(new_flat)
        new_mean, new_log_std = self.policy.apply(new_params, obs)
        kl = gaussian_kl(objective.old_mean, objective.old_log_std, new_mean, new_log_std)
        loss = objective.surrogate_loss
        metrics = {
            **metrics,
            "trpo/kl": jnp.mean(kl),
            "trpo/entropy": gaussian_entropy(new_log_std),
            "trpo/surrogate_improvement": loss(objective.flat_params) - loss(new_flat),
        }
        return new_params, metrics


def fisher_sample_indices(config: TRPOConfig) -> jax.Array:
    """Rows of the flattened time-major batch ([T, N] -> T * N) whose Fisher products TRPO
    uses: every ``fisher_subsample``-th time step of every environment, so each trajectory
    contributes (a stride over the flat batch would keep the same few environments)."""
    steps = jnp.arange(0, config.unroll_length, config.fisher_subsample)
    return (steps[:, None] * config.num_envs + jnp.arange(config.num_envs)).reshape(-1)


def gauss_newton_fisher_product(policy, unravel, flat_params, obs, damping):
    """v -> (J^T M J / N) v + damping v for a diagonal Gaussian policy.

    J is the Jacobian of (mean float[N, A], log_std float[A]) in the parameters and M the
    Fisher metric of a Gaussian in those coordinates: 1/sigma^2 per mean entry, 2 per log-std.
    At the current parameters this equals the Hessian of the mean KL (the reference's form).
    """
    num_samples = obs.shape[0]

    def outputs(flat):
        return policy.apply(unravel(flat), obs)

    (_, log_std), vjp = jax.vjp(outputs, flat_params)

    def product(v):
        _, (d_mean, d_log_std) = jax.jvp(outputs, (flat_params,), (v,))
        weighted = (d_mean * jnp.exp(-2 * log_std) / num_samples, 2.0 * d_log_std)
        return vjp(weighted)[0] + damping * v

    return product


def true_reward(transitions: Transitions) -> jax.Array:
    return transitions.reward


@struct.dataclass
class TRPOTrainState:
    """A TRPO-only run's state: the learner plus its fixed evaluation episode keys."""

    learner: TRPOState  # or another learner's state (PPOState)
    eval_keys: jax.Array  # key[num_eval_episodes], the same every evaluation


class TRPOTrainer:
    """TRPO (or another ``learner``, e.g. ``rl.PPO``) on a fixed reward (the environment's by
    default), in blocks.

    The trainer interface shared with ``pngail_jax.adversarial.AdversarialTrainer`` (and used by
    ``pngail_jax.grid.Grid``): ``init(*cell_inputs, key) -> (state, init_metrics)``,
    ``run_blocks(*cell_inputs, state, num_blocks) -> (state, metrics)`` and
    ``train(*cell_inputs, key)``, their composition. Here the cell inputs are one
    ``TRPOHyperparams`` (the learner's: ``PPOHyperparams`` for PPO). All three are pure and
    jittable; ``num_blocks`` is static.

    ``metrics`` map names to float[num_blocks * eval_every]; ``eval/return`` (the
    deterministic policy on ``num_eval_episodes`` fixed-key episodes) is set at the end of
    each block of ``eval_every`` iterations and NaN elsewhere; ``rollout/nonfinite_actions``
    counts each iteration's steps that applied a NaN or inf action (0 in a healthy run).
    """

    def __init__(
        self,
        config: TRPOConfig,
        env: envs.Env,
        reward_fn: RewardFunction = true_reward,
        learner: OnPolicyLearner | None = None,
    ):
        self.config = config
        self.env = env
        self.learner = TRPO(config, env) if learner is None else learner
        if self.learner.config != config:
            raise ValueError("TRPOTrainer: the learner was built with another TRPOConfig")
        self.reward_fn = reward_fn

    @property
    def eval_every(self) -> int:
        """Iterations per block of ``run_blocks`` (``grid.Trainer``)."""
        return self.config.eval_every

    def init(self, hyperparams: TRPOHyperparams, key: jax.Array):
        self.learner.check_hyperparams(hyperparams)  # init reads none, but the blocks will
        init_key, eval_key = jax.random.split(key)
        state = TRPOTrainState(
            learner=self.learner.init(init_key),
            eval_keys=jax.random.split(eval_key, self.config.num_eval_episodes),
        )
        return state, {}

    def _iteration(self, hyperparams: TRPOHyperparams, state: TRPOState):
        state, transitions = self.learner.rollout(state)
        rewards = self.reward_fn(transitions)
        state, metrics = self.learner.update(hyperparams, state, transitions, rewards)
        return state, {**metrics, "env_steps": state.env_steps}

    def run_blocks(
        self, hyperparams: TRPOHyperparams, state: TRPOTrainState, num_blocks: int
    ) -> tuple[TRPOTrainState, dict]:
        learner_state, metrics = run_evaluated_blocks(
            self.learner,
            functools.partial(self._iteration, hyperparams),
            state.learner,
            lambda s: s,
            state.eval_keys,
            num_blocks,
        )
        return state.replace(learner=learner_state), metrics

    def train(self, hyperparams: TRPOHyperparams, key: jax.Array):
        state, init_metrics = self.init(hyperparams, key)
        state, metrics = self.run_blocks(hyperparams, state, self.config.num_evaluations)
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: TRPOTrainState) -> TRPOState:
        """The learner's state inside a trainer state (for exporting its policy)."""
        return state.learner


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
