"""TRPO in pure JAX: the learner (``TRPO``: value fit, advantages, the natural-gradient step of
the policy) and its maths (Fisher-vector products, conjugate gradient, line search).

Static settings are two frozen configs: the rollout's shape and the iteration counts that
both learners share (``rl.on_policy.RolloutConfig``) and TRPO's own loop counts and Fisher
product (``TRPOConfig``); everything a grid may vary (discount, KL bound, learning rate,
whether to bootstrap through truncation) is a ``TRPOHyperparams`` pytree. Defaults are the
paper's and the reference code's (``docs/trpo.md``), except that GAE bootstraps the value
through time-limit truncation (``bootstrap_truncation``). Every loop but the line search
has a fixed iteration count and uses masks instead of early exits, so all cells of a vmapped
grid do the same work; the line search stops at the first fraction it takes, with the result
of trying them all (docs/architecture.md).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.flatten_util import ravel_pytree

from pngail_jax import envs
from pngail_jax.config.learner import TRPOConfig, check_hyperparam
from pngail_jax.networks import gaussian_entropy, gaussian_kl, gaussian_log_prob
from pngail_jax.rl.gae import generalized_advantages
from pngail_jax.rl.on_policy import (
    ObservationNormalizer,
    OnPolicyLearner,
    RolloutConfig,
    episode_metrics,
)
from pngail_jax.rl.rollout import Transitions, rollout_metrics


def conjugate_gradient(
    matrix_vector_product: Callable[[jax.Array], jax.Array],
    b: jax.Array,
    num_iterations: int,
    residual_tolerance: float = 1e-10,
) -> jax.Array:
    """Approximately solves A x = b for symmetric positive-definite A, from x = 0.

    Runs exactly ``num_iterations`` products; once the squared residual is below
    ``residual_tolerance`` the remaining iterations leave x unchanged (the reference breaks
    out of its loop there).
    """

    def body(carry, _):
        x, r, p, r_dot_r = carry
        active = r_dot_r >= residual_tolerance
        a_p = matrix_vector_product(p)
        alpha = jnp.where(active, r_dot_r / jnp.maximum(jnp.vdot(p, a_p), 1e-30), 0.0)
        x = x + alpha * p
        r = r - alpha * a_p
        new_r_dot_r = jnp.vdot(r, r)
        beta = jnp.where(active, new_r_dot_r / jnp.maximum(r_dot_r, 1e-30), 0.0)
        p = jnp.where(active, r + beta * p, p)
        return (x, r, p, jnp.where(active, new_r_dot_r, r_dot_r)), None

    initial = (jnp.zeros_like(b), b, b, jnp.vdot(b, b))
    (x, _, _, _), _ = jax.lax.scan(body, initial, None, length=num_iterations)
    return x


def backtracking_line_search(
    loss: Callable[[jax.Array], jax.Array],
    x: jax.Array,
    full_step: jax.Array,
    expected_improvement: jax.Array,
    num_backtracks: int = 10,
    accept_ratio: float = 0.1,
) -> tuple[jax.Array, jax.Array, jax.Array]:
    """The reference's line search over fractions 0.5^k, k = 0..num_backtracks-1.

    Takes the first fraction whose actual improvement is positive and more than
    ``accept_ratio`` times the expected (linear) improvement; keeps ``x`` if none is. The
    fractions are tried in order and the search stops at the first it takes, as the
    reference's loop breaks (under ``vmap`` the loop runs until every cell has taken one or
    run out). Evaluating all of them side by side instead cost 14 times as much on a CPU
    (docs/performance.md, "A shorter iteration") for the same result.

    Returns ``(new_x, accepted, fraction)``: fraction is 0 when no step was accepted.
    """
    base_loss = loss(x)
    zero = jnp.zeros((), x.dtype)

    def untried(carry):
        k, accepted, _ = carry
        return (k < num_backtracks) & ~accepted

    def try_next(carry):
        k, _, _ = carry
        fraction = 0.5 ** k.astype(x.dtype)
        actual = base_loss - loss(x + fraction * full_step)
        acceptable = (actual / (expected_improvement * fraction) > accept_ratio) & (actual > 0)
        return k + 1, acceptable, jnp.where(acceptable, fraction, zero)

    _, accepted, fraction = jax.lax.while_loop(
        untried, try_next, (jnp.zeros((), jnp.int32), jnp.zeros((), bool), zero)
    )
    return x + fraction * full_step, accepted, fraction


def natural_gradient_step(
    surrogate_loss: Callable[[jax.Array], jax.Array],
    mean_kl: Callable[[jax.Array], jax.Array],
    flat_params: jax.Array,
    max_kl: float | jax.Array,
    damping: float | jax.Array,
    num_cg_iterations: int,
    num_backtracks: int,
    fisher_vector_product: Callable[[jax.Array], jax.Array] | None = None,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """One TRPO update of flat parameters, as the reference's ``trpo_step``.

    Args:
      surrogate_loss: params -> float[], the loss to minimise (-advantage-weighted ratio).
      mean_kl: params -> float[], mean KL(pi_old || pi_params), 0 at ``flat_params``.
      fisher_vector_product: v -> (F + damping I) v; by default the Hessian of ``mean_kl``
        times v (the reference's form) plus damping.

    Returns ``(new_flat_params, metrics)`` with ``trpo/accepted`` (0/1), ``trpo/step_fraction``,
    ``trpo/expected_improvement``.
    """
    loss_grad = jax.grad(surrogate_loss)(flat_params)
    if fisher_vector_product is None:
        fisher_vector_product = hessian_vector_product(mean_kl, flat_params, damping)
    step_direction = conjugate_gradient(fisher_vector_product, -loss_grad, num_cg_iterations)
    shs = 0.5 * jnp.vdot(step_direction, fisher_vector_product(step_direction))
    lagrange_multiplier = jnp.sqrt(jnp.maximum(shs, 1e-30) / max_kl)
    full_step = step_direction / lagrange_multiplier
    expected_improvement = jnp.vdot(-loss_grad, step_direction) / lagrange_multiplier
    new_params, accepted, fraction = backtracking_line_search(
        surrogate_loss, flat_params, full_step, expected_improvement, num_backtracks
    )
    metrics = {
        "trpo/accepted": accepted.astype(flat_params.dtype),
        "trpo/step_fraction": fraction,
        "trpo/expected_improvement": expected_improvement,
    }
    return new_params, metrics


def hessian_vector_product(
    function: Callable[[jax.Array], jax.Array], at: jax.Array, damping: float | jax.Array
) -> Callable[[jax.Array], jax.Array]:
    """v -> (Hessian of ``function`` at ``at``) v + damping v, by forward-over-reverse."""
    gradient = jax.grad(function)

    def product(v):
        return jax.jvp(gradient, (at,), (v,))[1] + damping * v

    return product


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
            check_hyperparam("trpo", name, value)
        return cls(
            **{k: jnp.asarray(v, jnp.float32) for k, v in floats.items()},
            bootstrap_truncation=jnp.asarray(bootstrap_truncation, bool),
        )


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


@struct.dataclass
class TRPOState:
    policy_params: dict
    value_params: dict
    value_optimizer_state: optax.OptState
    normalizer: ObservationNormalizer
    env_state: envs.AutoResetState
    env_steps: jax.Array
    key: jax.Array


class TRPO(OnPolicyLearner):
    """The pieces of a TRPO run for one environment and static config.

    ``init``, ``rollout``, ``update`` and ``evaluate`` are pure; an adversarial trainer calls
    ``rollout``, computes its own rewards and calls ``update`` with them.
    """

    LEARNED_FIELDS = ("policy_params", "value_params", "value_optimizer_state", "normalizer")
    HYPERPARAMS = TRPOHyperparams

    def __init__(self, config: RolloutConfig, env: envs.Env, trpo: TRPOConfig | None = None):
        trpo = TRPOConfig() if trpo is None else trpo
        trpo.check_batch(config)
        super().__init__(config, env)
        self.trpo = trpo
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
        """The update's value step: Adam over ``num_value_epochs`` permutations of the
        flattened batch (obs float[B, O], targets float[B]), each in ``num_value_minibatches``
        steps (the first permutation is ``key``'s, the e-th ``fold_in(key, e)``'s). Returns the
        value parameters, their optimiser state and the mean loss."""
        num_minibatches = self.trpo.num_value_minibatches
        minibatch_size = self.config.batch_size // num_minibatches
        epoch_keys = [key] + [
            jax.random.fold_in(key, epoch) for epoch in range(1, self.trpo.num_value_epochs)
        ]
        orders = [
            jax.random.permutation(epoch_key, self.config.batch_size)[
                : num_minibatches * minibatch_size
            ].reshape(num_minibatches, minibatch_size)
            for epoch_key in epoch_keys
        ]
        order = orders[0] if len(orders) == 1 else jnp.concatenate(orders)  # 1: the same program

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
        fisher_rows = fisher_sample_indices(self.config, self.trpo.fisher_subsample)
        fisher_obs, fisher_old_mean = obs[fisher_rows], old_mean[fisher_rows]

        def surrogate_loss(flat):
            mean, log_std = self.policy.apply(unravel(flat), obs)
            ratio = jnp.exp(gaussian_log_prob(mean, log_std, actions) - old_log_prob)
            return -jnp.mean(advantages * ratio)

        def mean_kl(flat):
            mean, log_std = self.policy.apply(unravel(flat), fisher_obs)
            return jnp.mean(gaussian_kl(fisher_old_mean, old_log_std, mean, log_std))

        if self.trpo.fisher == "gauss_newton":
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
            self.trpo.num_cg_iterations,
            self.trpo.num_backtracks,
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


def fisher_sample_indices(config: RolloutConfig, fisher_subsample: int) -> jax.Array:
    """Rows of the flattened time-major batch ([T, N] -> T * N) whose Fisher products TRPO
    uses: every ``fisher_subsample``-th time step of every environment, so each trajectory
    contributes (a stride over the flat batch would keep the same few environments)."""
    steps = jnp.arange(0, config.unroll_length, fisher_subsample)
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
