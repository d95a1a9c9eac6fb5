"""f-IRL (Ni et al., 2021) as its codebase runs it on MuJoCo (twni2016/f-IRL,
``firl/irl_samples.py``, ``firl/divs/f_div_disc.py``, ``firl/models/{discrim,reward}.py``).

A state reward r_theta(s) follows the gradient of an f-divergence between the demonstrations'
and the agent's state marginals (their Theorem 4.1). With u = rho_E(s) / rho_theta(s) and
h_f(u) = f(u) - u f'(u), that gradient is a covariance over trajectories,

    grad = Cov_tau ( sum_t h_f(u(s_t)),  sum_t grad r_theta(s_t) ),

and log u is estimated by a state discriminator trained to tell demonstration states
(label 1) from agent states: log u = its logit l, clamped to [-10, 10]. Their code writes the
first factor as t1 = -sum_t h(l), with h as coded (each -h equals the paper's h_f up to a
constant, which a covariance ignores):

| divergence | f(u) | h_f(u) | h(l) as coded |
|---|---|---|---|
| forward KL, KL(rho_E || rho) | u log u | -u | exp(l) |
| reverse KL, KL(rho || rho_E) | -log u | 1 - log u | l |
| Jensen-Shannon | u log u - (1 + u) log((1 + u) / 2) | log 2 - log(1 + u) | softplus(l) |

and the reward loss, which Adam minimises, is the biased sample covariance over the N
trajectories divided by their length T:

    loss = ( mean(t1 t2) - mean(t1) mean(t2) ) / T,   t2 = sum_t r_theta(s_t).

Its batch holds the agent's trajectories *and* as many resampled demonstration trajectories.
Per outer iteration their code refits the discriminator (1,200 Adam steps, 800 + 800 states
drawn with replacement, warm-started), then takes one Adam step of the reward. Both Adams
carry torch's coupled L2 weight decay. ``FirlConfig`` holds those settings; ``docs/methods.md``
lists them beside ours. A divergence is data (three coefficients of ``MethodSpec``), so FKL,
RKL and JS cells share one program.
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from pngail_jax.adversarial.phase import Phase, PhaseContext
from pngail_jax.networks import ClampedStateReward, ResidualDiscriminator


@dataclasses.dataclass(frozen=True)
class FirlConfig:
    """Static settings of f-IRL's phase; the defaults are its codebase's MuJoCo values
    (``configs/samples/agents/{hopper,halfcheetah,walker2d}.yml``; ``for_env("Ant")`` gives
    ant.yml's wider networks)."""

    # The density-ratio state discriminator (``disc``): Adam steps per outer iteration, states
    # per side per step (drawn with replacement), Adam lr, coupled L2 weight decay.
    discriminator_iterations: int = 1_200
    discriminator_batch_size: int = 800
    discriminator_learning_rate: float = 3e-4
    discriminator_weight_decay: float = 1e-4
    discriminator_hidden_size: int = 128
    # num_layer_blocks - 1 of theirs: 3 - 1 on MuJoCo tasks, 6 - 1 on Ant.
    discriminator_residual_blocks: int = 2
    # The reward (``reward``): one Adam step per outer iteration.
    reward_hidden_sizes: tuple[int, ...] = (64, 64)
    reward_learning_rate: float = 1e-4
    reward_weight_decay: float = 1e-3
    # Both networks' outputs are clamped to [-clamp_magnitude, clamp_magnitude].
    clamp_magnitude: float = 10.0

    def __post_init__(self):
        for name in ("discriminator_iterations", "discriminator_batch_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"FirlConfig.{name} must be a positive integer, got {value!r}")
        blocks = self.discriminator_residual_blocks
        if isinstance(blocks, bool) or not isinstance(blocks, int) or blocks < 0:
            raise ValueError(
                f"FirlConfig.discriminator_residual_blocks must be an integer >= 0, got {blocks!r}"
            )
        sizes = (self.discriminator_hidden_size, *self.reward_hidden_sizes)
        if not self.reward_hidden_sizes or not all(
            isinstance(size, int) and size >= 1 for size in sizes
        ):
            raise ValueError(
                "FirlConfig.discriminator_hidden_size and reward_hidden_sizes must be positive "
                f"integers (at least one reward layer), got {sizes!r}"
            )
        for name in ("discriminator_learning_rate", "reward_learning_rate", "clamp_magnitude"):
            if not getattr(self, name) > 0:
                raise ValueError(f"FirlConfig.{name} must be positive, got {getattr(self, name)!r}")
        for name in ("discriminator_weight_decay", "reward_weight_decay"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"FirlConfig.{name} must be >= 0, got {getattr(self, name)!r}")

    @classmethod
    def for_env(cls, env_name: str) -> FirlConfig:
        """The codebase's settings for ``env_name``: ant.yml's (5 residual blocks, a
        (128, 128) reward) for Ant, the other MuJoCo files' (the defaults) for any other."""
        from pngail_jax.envs import task_family

        if task_family(env_name) == "Ant":
            return cls(discriminator_residual_blocks=5, reward_hidden_sizes=(128, 128))
        return cls()


def adam_with_l2(learning_rate: float, weight_decay: float) -> optax.GradientTransformation:
    """``torch.optim.Adam(lr, weight_decay, betas=(0.9, 0.999), eps=1e-8)``: the decay is
    added to the gradient *before* Adam's moments (coupled L2, not AdamW's decoupled decay).
    ``update`` needs the params."""
    return optax.chain(
        optax.add_decayed_weights(weight_decay),
        optax.scale_by_adam(b1=0.9, b2=0.999, eps=1e-8),
        optax.scale(-learning_rate),
    )


def divergence_h(log_ratio: jax.Array, fkl_coef, rkl_coef, js_coef) -> jax.Array:
    """h(l) of ``f_div_disc_loss`` for the divergence mixing FKL, RKL and JS by the coefs:
    exp(l), l and softplus(l); -h is h_f up to a constant. ``log_ratio`` float[...] is the
    clamped logit (|l| <= 10, so exp(l) stays finite in every cell of a grid)."""
    return (
        fkl_coef * jnp.exp(log_ratio) + rkl_coef * log_ratio + js_coef * jax.nn.softplus(log_ratio)
    )


def covariance_surrogate(h_sums: jax.Array, reward_sums: jax.Array, num_steps: int):
    """f-IRL's reward loss: ``((t1 t2).mean() - t1.mean() t2.mean()) / T``, t1 = -h_sums.

    h_sums float[N]: sum_t h(l(s_t)) over each of N trajectories (no gradient flows through
    it); reward_sums float[N]: sum_t r_theta(s_t); num_steps: T, the steps per trajectory.
    Its gradient is (1 / T) Cov_N(t1, sum_t grad r_theta), the biased (1 / N) covariance.
    Returns ``(loss, metrics)``.
    """
    chex.assert_equal_shape([h_sums, reward_sums])
    t1 = -jax.lax.stop_gradient(h_sums)
    loss = ((t1 * reward_sums).mean() - t1.mean() * reward_sums.mean()) / num_steps
    return loss, {"firl/loss": loss, "firl/t1_std": jnp.std(t1) / num_steps}


def state_discriminator_loss(logits_expert: jax.Array, logits_agent: jax.Array):
    """``BCEWithLogitsLoss`` over the concatenated logits, expert states label 1, agent
    states 0 (a mean over all B_e + B_a logits): with equal batches its optimum logit is
    log rho_E(s) / rho_agent(s). logits_expert float[B_e], logits_agent float[B_a]."""
    total = jnp.sum(jax.nn.softplus(-logits_expert)) + jnp.sum(jax.nn.softplus(logits_agent))
    loss = total / (logits_expert.shape[0] + logits_agent.shape[0])
    return loss, {"firl/disc_loss": loss}


def fit_discriminator(
    apply, optimizer, params, optimizer_state, expert_states, agent_states, num_iterations,
    batch_size, key,
):  # fmt: skip
    """Refits the state discriminator (``SMMIRLDisc.learn``): ``num_iterations`` Adam steps,
    each on ``batch_size`` expert and ``batch_size`` agent states drawn uniformly with
    replacement. Warm-started: it continues from ``params`` and ``optimizer_state``.

    apply(params, states float[B, O]) -> logits float[B]; expert_states float[M, O];
    agent_states float[K, O]. Returns ``(params, optimizer_state, losses float[num_iterations])``.
    """

    def step(carry, key):
        params, optimizer_state = carry
        expert_key, agent_key = jax.random.split(key)
        expert = expert_states[
            jax.random.randint(expert_key, (batch_size,), 0, expert_states.shape[0])
        ]
        agent = agent_states[jax.random.randint(agent_key, (batch_size,), 0, agent_states.shape[0])]

        def loss_fn(params):
            return state_discriminator_loss(apply(params, expert), apply(params, agent))

        loss, grads = jax.value_and_grad(lambda p: loss_fn(p)[0])(params)
        updates, optimizer_state = optimizer.update(grads, optimizer_state, params)
        return (optax.apply_updates(params, updates), optimizer_state), loss

    keys = jax.random.split(key, num_iterations)
    (params, optimizer_state), losses = jax.lax.scan(step, (params, optimizer_state), keys)
    return params, optimizer_state, losses


@struct.dataclass
class SegmentSource:
    """Where demonstration segments come from: ``rows`` int32[L], demonstration rows in
    order (each trajectory's steps consecutive), and K trajectories in it, ``starts``
    int32[K] and ``lengths`` int32[K] (positions in ``rows``)."""

    rows: jax.Array
    starts: jax.Array
    lengths: jax.Array

    @classmethod
    def of_trajectories(cls, trajectory_ids) -> SegmentSource:
        """Host-side: the demonstration set's trajectories (``trajectory_ids`` int[N]), in
        the order of their first row, each one's rows in row order."""
        ids = np.asarray(trajectory_ids)
        _, first_row, trajectory = np.unique(ids, return_index=True, return_inverse=True)
        rank = np.argsort(np.argsort(first_row))[trajectory]  # by first appearance
        lengths = np.bincount(rank)
        starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
        rows = np.argsort(rank, kind="stable")
        return cls(*(jnp.asarray(a, jnp.int32) for a in (rows, starts, lengths)))

    @classmethod
    def of_rows(cls, rows: jax.Array) -> SegmentSource:
        """Rows without trajectories: every position starts a one-row "trajectory", so a
        segment is ``length`` consecutive entries of ``rows`` (wrapping at the end)."""
        num = rows.shape[0]
        return cls(rows, jnp.arange(num, dtype=jnp.int32), jnp.ones(num, jnp.int32))


def sample_segment_rows(key, source: SegmentSource, num_segments: int, length: int):
    """Demonstration rows of ``num_segments`` resampled trajectory segments, int32[length,
    num_segments] (time-major, as a rollout's ``obs``).

    Trajectories are drawn as f-IRL resamples its expert trajectories: without replacement
    when there are at least ``num_segments`` (their 10 of 16), with replacement otherwise
    (their 10 of 4). Each segment is ``length`` consecutive rows of ``source.rows`` from a
    uniform start where they fit inside the trajectory, else from its first row on into the
    next trajectory (as an agent's segment runs on after a reset), wrapping at the end.
    """
    choice_key, start_key = jax.random.split(key)
    num_trajectories = source.starts.shape[0]
    chosen = jax.random.choice(
        choice_key, num_trajectories, (num_segments,), replace=num_trajectories < num_segments
    )
    room = jnp.maximum(source.lengths[chosen] - length, 0) + 1  # possible starts
    offset = jnp.floor(jax.random.uniform(start_key, (num_segments,)) * room).astype(jnp.int32)
    first = source.starts[chosen] + offset
    positions = (first[None, :] + jnp.arange(length)[:, None]) % source.rows.shape[0]
    return source.rows[positions]


@struct.dataclass
class FirlState:
    """f-IRL's reward r(s) and state discriminator, with their Adam states (both kept from
    one iteration to the next, as its codebase never rebuilds them)."""

    reward_params: dict
    reward_optimizer_state: optax.OptState
    discriminator_params: dict
    discriminator_optimizer_state: optax.OptState


class FirlPhase(Phase):
    """f-IRL in the adversarial trainer: its reward and state discriminator networks, their
    optimisers, and where its demonstration segments come from (the set's trajectories when
    it has trajectory ids, else consecutive split rows). In every iteration ``outer_step``
    runs before any other step, and the policy's reward gains ``spec.firl_coef`` r(s)."""

    names = ("firl",)

    def __init__(self, config: FirlConfig, trajectory_ids=None):
        self.config = config
        self.state_discriminator = ResidualDiscriminator(
            config.discriminator_hidden_size, config.discriminator_residual_blocks,
            config.clamp_magnitude,
        )  # fmt: skip
        self.state_reward = ClampedStateReward(config.reward_hidden_sizes, config.clamp_magnitude)
        self.discriminator_optimizer = adam_with_l2(
            config.discriminator_learning_rate, config.discriminator_weight_decay
        )
        self.reward_optimizer = adam_with_l2(
            config.reward_learning_rate, config.reward_weight_decay
        )
        self.segments = (
            None if trajectory_ids is None else SegmentSource.of_trajectories(trajectory_ids)
        )

    def initial_state(self, observation_size: int, key: jax.Array) -> FirlState:
        """Fresh networks and Adam states."""
        reward_key, disc_key = jax.random.split(key)
        reward = self.state_reward.init(reward_key, jnp.zeros((observation_size,)))
        disc = self.state_discriminator.init(disc_key, jnp.zeros((observation_size,)))
        return FirlState(
            reward, self.reward_optimizer.init(reward),
            disc, self.discriminator_optimizer.init(disc),
        )  # fmt: skip

    def init(self, context: PhaseContext, spec, inputs, confidence, learner_state, keys, ranked):
        return {"firl": self.initial_state(context.env.observation_size, keys.firl)}, learner_state

    def reward(self, context: PhaseContext, spec, state, transitions, batch, key):
        firl_state, metrics = self.outer_step(
            context, spec, state, transitions.obs, jax.random.fold_in(key, 2)
        )
        term = spec.firl_coef * self.state_reward.apply(firl_state.reward_params, batch.agent_obs)
        return term, {"firl": firl_state}, metrics

    def outer_step(self, context: PhaseContext, spec, state, agent_obs, key):
        """f-IRL's outer step (its codebase's ``firl/irl_samples.py``): the state
        discriminator refitted (warm-started) on the split's states against this rollout's,
        then one Adam step of the reward on the covariance loss over the rollout's
        ``num_envs`` segments of ``unroll_length`` steps (agent_obs float[T, E, O], our
        stand-in for their sampled trajectories) and as many resampled demonstration
        segments. ``state`` needs ``firl`` and ``demo_rows``. Returns (FirlState, metrics)."""
        config, num_envs, length = self.config, context.num_envs, context.unroll_length
        size = context.env.observation_size
        firl_state = state.firl
        discriminator_key, segment_key = jax.random.split(key)
        disc_params, disc_optimizer_state, disc_losses = fit_discriminator(
            self.state_discriminator.apply, self.discriminator_optimizer,
            firl_state.discriminator_params, firl_state.discriminator_optimizer_state,
            context.demo_inputs[state.demo_rows, :size], agent_obs.reshape(-1, size),
            config.discriminator_iterations, config.discriminator_batch_size, discriminator_key,
        )  # fmt: skip
        source = self.segments
        if source is None:  # no trajectory ids: segments of consecutive split rows
            source = SegmentSource.of_rows(state.demo_rows)
        expert_rows = sample_segment_rows(segment_key, source, num_envs, length)
        expert_obs = context.demo_inputs[expert_rows, :size]  # float[T, E, O]
        segments = jnp.concatenate([agent_obs, expert_obs], axis=1)  # float[T, 2E, O]
        log_ratio = self.state_discriminator.apply(disc_params, segments)  # log rho_E / rho
        h = divergence_h(log_ratio, spec.firl_fkl_coef, spec.firl_rkl_coef, spec.firl_js_coef)

        def reward_loss_fn(params):
            rewards = self.state_reward.apply(params, segments)  # float[T, 2E]
            loss, metrics = covariance_surrogate(h.sum(axis=0), rewards.sum(axis=0), length)
            agent, expert = jnp.split(rewards, 2, axis=1)
            means = {"firl/reward_agent": agent.mean(), "firl/reward_expert": expert.mean()}
            return loss, {**metrics, **means}

        grads, reward_metrics = jax.grad(reward_loss_fn, has_aux=True)(firl_state.reward_params)
        updates, reward_optimizer_state = self.reward_optimizer.update(
            grads, firl_state.reward_optimizer_state, firl_state.reward_params
        )
        new_state = FirlState(
            optax.apply_updates(firl_state.reward_params, updates), reward_optimizer_state,
            disc_params, disc_optimizer_state,
        )  # fmt: skip
        metrics = {
            "firl/disc_loss": disc_losses[-1],
            "firl/disc_loss_first": disc_losses[0],
            "firl/log_ratio_agent": log_ratio[:, :num_envs].mean(),
            "firl/log_ratio_expert": log_ratio[:, num_envs:].mean(),
            **reward_metrics,
        }
        return new_state, metrics
