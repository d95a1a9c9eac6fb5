"""CAIL (Zhang et al., 2021) as its codebase runs it, on this project's GAIL discriminator.

CAIL learns a confidence beta for every demonstration state-action pair together with the
discriminator. Each iteration runs ``CAILConfig.num_rounds`` rounds of:

1. **renormalise**: ``beta <- clip(beta / mean(beta), 0, beta_max)`` (mean over every row);
2. **lookahead**: one plain gradient step of the confidence-weighted discriminator loss on a
   batch of B agent and B demonstration pairs,
   ``theta' = theta - lookahead_lr * grad_theta L(theta, beta)``, with
   ``L = mean_agent sp(-z) + mean_demo beta sp(z)`` (agent label 1, ``sp`` softplus);
3. **outer step on beta**: ``beta <- beta - confidence_lr * grad_beta L_rank(theta'(beta))``,
   where ``L_rank`` is the margin ranking loss (margin 0) over *all pairs* of
   ``num_trajectories`` whole ranked trajectories drawn with replacement, of the summed reward
   ``R(tau) = sum_t sp(-z_theta'(s_t, a_t))``; the gradient reaches beta through the lookahead
   (second order);
4. **renormalise** again, then one Adam step of the discriminator on a fresh batch with beta
   held fixed (optionally only when that step's gradient agrees with the ranking loss's, see
   ``pretrain_iterations``).

Everything here is pure and jittable; ``CailPhase`` is its phase in the adversarial trainer's
one-program grid (``pngail_jax.adversarial.phase``).
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp

from pngail_jax.adversarial.losses import policy_reward
from pngail_jax.adversarial.phase import Phase, PhaseContext
from pngail_jax.fitting import adam_step, gradients_agree, tree_where

# The codebase's smoothing of the hinge where two returns differ by less than this.
SMOOTHING = 1e-5


@dataclasses.dataclass(frozen=True)
class CAILConfig:
    """Static settings; defaults are the CAIL codebase's (``docs/methods.md`` lists them).

    ``pretrain_iterations``: from this iteration on, the discriminator steps only when the dot
    product of its gradient with the ranking loss's gradient (at the current parameters) is
    >= 0. None never gates, which is what the codebase does as configured: its gate compares a
    count of PPO iterations with a threshold in environment steps, which it never reaches.
    """

    num_rounds: int = 10  # confidence and discriminator updates per iteration
    batch_size: int = 100  # agent and demonstration pairs per lookahead and per real step
    num_trajectories: int = 20  # ranked trajectories per outer loss (all pairs among them)
    lookahead_learning_rate: float = 3e-4  # the lookahead's plain gradient step
    discriminator_learning_rate: float = 3e-4  # Adam, CAIL cells' discriminator
    beta_max: float = 2.0  # beta is clipped to [0, beta_max] after each renormalisation
    pretrain_iterations: int | None = None

    def __post_init__(self):
        for name in ("num_rounds", "batch_size", "num_trajectories"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"CAILConfig.{name} must be a positive integer, got {value!r}")
        if self.num_trajectories < 2:
            raise ValueError("CAILConfig.num_trajectories must be at least 2 (pairs of them)")
        for name in ("lookahead_learning_rate", "discriminator_learning_rate", "beta_max"):
            if not getattr(self, name) > 0:
                raise ValueError(f"CAILConfig.{name} must be positive")
        if self.pretrain_iterations is not None and (
            isinstance(self.pretrain_iterations, bool)
            or not isinstance(self.pretrain_iterations, int)
            or self.pretrain_iterations < 0
        ):
            raise ValueError("CAILConfig.pretrain_iterations must be None or an integer >= 0")


def renormalize(beta: jax.Array, beta_max: float) -> jax.Array:
    """``clip(beta / mean(beta), 0, beta_max)`` over every row (float[M])."""
    return jnp.clip(beta / jnp.mean(beta), 0.0, beta_max)


def inner_loss(logits_agent: jax.Array, logits_demo: jax.Array, beta: jax.Array):
    """CAIL's confidence-weighted discriminator loss ``mean_agent sp(-z) + mean_demo beta
    sp(z)`` (a plain mean over the batch, no division by the sum of beta).

    logits_agent float[B_a], logits_demo float[B_d], beta float[B_d]. Returns the loss."""
    chex.assert_equal_shape([logits_demo, beta])
    return jnp.mean(jax.nn.softplus(-logits_agent)) + jnp.mean(beta * jax.nn.softplus(logits_demo))


def margin_ranking_loss(returns: jax.Array, truth: jax.Array):
    """Sum over all pairs i < j of the sampled trajectories of the hinge ``max(0, -y (R_i -
    R_j))``, ``y = sign(truth_i - truth_j)``, margin 0; a pair whose returns differ by less
    than ``SMOOTHING`` takes ``(|R_i - R_j| - SMOOTHING)^2 / (4 SMOOTHING)`` instead (the
    codebase's smoothing). Pairs of equal truth (the same trajectory drawn twice) count 0.

    returns, truth: float[N]. Returns ``(loss, metrics)``: the pair accuracy among informative
    pairs.
    """
    chex.assert_equal_shape([returns, truth])
    num = returns.shape[0]
    upper = jnp.triu(jnp.ones((num, num), bool), k=1)
    difference = returns[:, None] - returns[None, :]
    sign = jnp.sign(truth[:, None] - truth[None, :])
    informative = upper & (sign != 0)
    hinge = jnp.maximum(0.0, -sign * difference)
    smoothed = (jnp.abs(difference) - SMOOTHING) ** 2 / (4 * SMOOTHING)
    per_pair = jnp.where(jnp.abs(difference) < SMOOTHING, smoothed, hinge)
    loss = jnp.sum(jnp.where(informative, per_pair, 0.0))
    correct = jnp.sum(informative & (sign * difference > 0))
    accuracy = correct / jnp.maximum(informative.sum(), 1)
    return loss, {"cail/ranking_loss": loss, "cail/ranking_accuracy": accuracy}


def trajectory_returns(reward_of, features: jax.Array, valid: jax.Array) -> jax.Array:
    """``sum_t reward_of(features[n, t])`` over the valid steps of each trajectory.

    features float[N, T, F], valid bool[N, T]; ``reward_of`` maps float[..., F] to float[...].
    Returns float[N]."""
    return jnp.sum(jnp.where(valid, reward_of(features), 0.0), axis=1)


def iteration_rounds(context: PhaseContext, config: CAILConfig, spec, state, agent_inputs, key):
    """CAIL's ``num_rounds`` rounds in an iteration of the adversarial trainer: per round,
    the lookahead, the outer step on beta, and one Adam step of the discriminator on a
    fresh batch. agent_inputs float[N, O + A] is this iteration's rollout; ``state`` the
    trainer's state before the iteration. Returns ``((discriminator params, its Adam state,
    beta float[M]), metrics)``, the metrics averaged over the rounds."""
    batch_loss, ranking_loss = _round_losses(context, state, agent_inputs)
    ranked = state.ranked_trajectories.astype(jnp.float32)
    num_agent = agent_inputs.shape[0]

    def round_(carry, round_key):
        params, optimizer_state, beta = carry
        index_key, agent_key, demo_key, step_agent_key, step_demo_key = jax.random.split(
            round_key, 5
        )
        index = jax.random.choice(
            index_key, ranked.shape[0], (config.num_trajectories,), p=ranked / ranked.sum()
        )
        rows = lambda k, n: jax.random.randint(k, (config.batch_size,), 0, n)  # noqa: E731
        agent_rows, demo_rows = rows(agent_key, num_agent), rows(demo_key, context.num_demos)
        beta = renormalize(beta, config.beta_max)

        def outer_loss(beta):
            grads = jax.grad(batch_loss)(params, beta, agent_rows, demo_rows)
            lookahead = jax.tree.map(
                lambda p, g: p - config.lookahead_learning_rate * g, params, grads
            )
            return ranking_loss(lookahead, index)

        beta_grads, metrics = jax.grad(outer_loss, has_aux=True)(beta)
        beta = renormalize(beta - spec.cail_learning_rate * beta_grads, config.beta_max)
        step_rows = rows(step_agent_key, num_agent), rows(step_demo_key, context.num_demos)
        loss, grads = jax.value_and_grad(batch_loss)(params, beta, *step_rows)
        new_params, new_optimizer_state = adam_step(
            params, optimizer_state, grads, config.discriminator_learning_rate
        )
        skipped = jnp.zeros(())
        if config.pretrain_iterations is not None:  # step only where the gradients agree
            ranking_grads = jax.grad(lambda p: ranking_loss(p, index)[0])(params)
            step = gradients_agree(grads, ranking_grads) | (
                state.iteration < config.pretrain_iterations
            )
            new_params = tree_where(step, new_params, params)
            new_optimizer_state = tree_where(step, new_optimizer_state, optimizer_state)
            skipped = 1.0 - step.astype(jnp.float32)
        metrics = {**metrics, "cail/disc_loss": loss, "cail/skipped_steps": skipped}
        return (new_params, new_optimizer_state, beta), metrics

    carry = (state.discriminator_params, state.discriminator_optimizer_state)
    carry, metrics = jax.lax.scan(
        round_, (*carry, state.cail_confidence), jax.random.split(key, config.num_rounds)
    )
    metrics = jax.tree.map(jnp.mean, metrics)
    metrics["cail/skipped_steps"] *= config.num_rounds  # a count per iteration
    beta = carry[2]
    return carry, {**metrics, "cail/beta_std": beta.std(), "cail/beta_max": beta.max()}


def _round_losses(context: PhaseContext, state, agent_inputs):
    """A round's two losses of the discriminator's parameters: the confidence-weighted one on
    rows of the rollout and of the split, ``batch_loss(params, beta, agent_rows, demo_rows)``,
    and the margin ranking one on ranked trajectories, ``ranking_loss(params, index)``."""
    trajectories, discriminator = context.trajectories, context.discriminator
    features = jnp.concatenate([trajectories.observations, trajectories.actions], axis=-1)
    valid = trajectories.valid

    def batch_loss(params, beta, agent_rows, demo_rows):
        logits_agent = discriminator.apply(params, agent_inputs[agent_rows])
        logits_demo = discriminator.apply(params, context.demo_inputs[state.demo_rows[demo_rows]])
        return inner_loss(logits_agent, logits_demo, beta[demo_rows])

    def ranking_loss(params, index):
        returns = trajectory_returns(
            lambda x: policy_reward(discriminator.apply(params, x)),
            features[index],
            valid[index],
        )
        return margin_ranking_loss(returns, trajectories.score[index])

    return batch_loss, ranking_loss


class CailPhase(Phase):
    """CAIL in the adversarial trainer: beta starts at 1 on every split row; in CAIL's cells
    (``spec.cail_coef`` 1) its rounds replace the discriminator's Adam step of the iteration
    (every other cell of the grid keeps its own step)."""

    names = ("cail",)
    ranks_demonstrations = True

    def __init__(self, config: CAILConfig):
        self.config = config

    def init(self, context: PhaseContext, spec, inputs, confidence, learner_state, keys, ranked):
        return {"cail_confidence": jnp.ones(context.num_demos)}, learner_state

    def discriminator_step(self, context: PhaseContext, spec, state, batch, key, stepped):
        params, optimizer_state, metrics = stepped
        (cail_params, cail_optimizer_state, beta), cail_metrics = iteration_rounds(
            context, self.config, spec, state, batch.agent_inputs, jax.random.fold_in(key, 1)
        )
        use = spec.cail_coef > 0
        metrics = {
            **metrics,
            "disc/loss": jnp.where(use, cail_metrics["cail/disc_loss"], metrics["disc/loss"]),
        }
        stepped = (
            tree_where(use, cail_params, params),
            tree_where(use, cail_optimizer_state, optimizer_state),
            metrics,
        )
        return stepped, {"cail_confidence": beta}, cail_metrics

    @staticmethod
    def trajectory_confidence(context: PhaseContext, state) -> jax.Array:
        """float[K]: CAIL's mean beta over each demonstration trajectory's rows in the split
        (NaN for a trajectory with no row in it)."""
        trajectory = context.row_trajectory[state.demo_rows]
        num = context.trajectories.lengths.shape[0]
        total = jax.ops.segment_sum(state.cail_confidence, trajectory, num)
        count = jax.ops.segment_sum(jnp.ones_like(state.cail_confidence), trajectory, num)
        return jnp.where(count > 0, total / jnp.maximum(count, 1), jnp.nan)
