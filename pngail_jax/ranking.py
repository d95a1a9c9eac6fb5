"""Rewards learned from ranked trajectories (T-REX, D-REX) and CAIL's ranking loss.

T-REX (Brown et al., 2019) fits a state reward r(s) so that of two trajectory snippets the
better-ranked one has the larger summed reward, with the Bradley-Terry likelihood

    P(snippet j better than snippet i) = exp(R_j) / (exp(R_i) + exp(R_j)),   R = sum_t r(s_t),

and then runs RL on r. D-REX (Brown et al., 2020) makes its own rankings: rollouts of a
behaviour-cloned policy with epsilon-greedy noise, less noise ranked better. CAIL (Zhang et al.,
2021) uses the same loss on its adversarial reward as the outer objective of its bilevel
confidence update. Here the rankings of the demonstrations are their confidences (every
trajectory's, not only the labelled 20% PN-GAIL sees).

Every function is pure and jittable; ``Trajectories`` are padded to one length, so a grid can
``vmap`` over seeds and methods.
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.fitting import fit_with_adam
from pngail_jax.networks import MLP


@dataclasses.dataclass(frozen=True)
class RankingConfig:
    """Static settings of reward learning from rankings (T-REX's phase, D-REX's, CAIL's
    outer loss)."""

    num_steps: int = 2_000  # Adam steps of the reward network
    pairs_per_step: int = 32
    snippet_length: int = 50  # steps summed per snippet (whole trajectory when shorter)
    learning_rate: float = 1e-3
    hidden_sizes: tuple[int, ...] = (100, 100)
    # D-REX: epsilon-greedy noise levels of the cloned policy's rollouts, and rollouts per level.
    noise_levels: tuple[float, ...] = (1.0, 0.75, 0.5, 0.25, 0.02)
    rollouts_per_level: int = 2

    def __post_init__(self):
        for name in ("num_steps", "pairs_per_step", "snippet_length", "rollouts_per_level"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"RankingConfig.{name} must be a positive integer, got {value!r}")
        if not all(0 <= level <= 1 for level in self.noise_levels) or not self.noise_levels:
            raise ValueError(
                f"RankingConfig.noise_levels must lie in [0, 1], got {self.noise_levels}"
            )


@struct.dataclass
class Trajectories:
    """K trajectories padded to T steps.

    observations float[K, T, O], actions float[K, T, A], lengths int32[K] (steps before the
    padding), score float[K] (higher is better: the confidence, or minus the noise level).
    """

    observations: jax.Array
    actions: jax.Array
    lengths: jax.Array
    score: jax.Array

    @property
    def valid(self) -> jax.Array:
        """bool[K, T]: the steps that are not padding."""
        return jnp.arange(self.observations.shape[1]) < self.lengths[:, None]


def trajectories_of(observations, actions, trajectory_ids, confidence):
    """Host-side: the demonstrations' trajectories (``trajectory_ids`` int[N] group the rows,
    in row order) padded to the longest, each scored by its mean confidence, and int32[N]:
    each row's trajectory index among them. Returns ``(Trajectories, row_trajectory)``."""
    ids = np.asarray(trajectory_ids)
    order = list(dict.fromkeys(ids.tolist()))
    longest = max(int((ids == i).sum()) for i in order)
    shape = (len(order), longest)
    obs = np.zeros((*shape, observations.shape[1]), np.float32)
    act = np.zeros((*shape, actions.shape[1]), np.float32)
    lengths = np.zeros(len(order), np.int32)
    score = np.zeros(len(order), np.float32)
    for k, trajectory in enumerate(order):
        rows = np.flatnonzero(ids == trajectory)
        lengths[k] = len(rows)
        obs[k, : len(rows)] = observations[rows]
        act[k, : len(rows)] = actions[rows]
        score[k] = np.mean(confidence[rows])
    index_of = {trajectory: k for k, trajectory in enumerate(order)}
    row_trajectory = np.array([index_of[trajectory] for trajectory in ids.tolist()], np.int32)
    trajectories = Trajectories(
        jnp.asarray(obs), jnp.asarray(act), jnp.asarray(lengths), jnp.asarray(score)
    )
    return trajectories, jnp.asarray(row_trajectory)


@struct.dataclass
class SnippetPairs:
    """P pairs of snippets: trajectory indices and start steps of the worse and the better
    one, and ``weight`` float[P] (0 for a pair of equal scores, which says nothing)."""

    worse: jax.Array
    worse_start: jax.Array
    better: jax.Array
    better_start: jax.Array
    weight: jax.Array


def sample_pairs(
    key: jax.Array, trajectories: Trajectories, num_pairs: int, snippet_length: int
) -> SnippetPairs:
    """Two trajectories drawn uniformly per pair, ordered by score; each snippet starts
    uniformly where ``snippet_length`` steps fit (at 0 in a shorter trajectory)."""
    first_key, second_key, start_key = jax.random.split(key, 3)
    num = trajectories.lengths.shape[0]
    first = jax.random.randint(first_key, (num_pairs,), 0, num)
    second = jax.random.randint(second_key, (num_pairs,), 0, num)
    first_better = trajectories.score[first] > trajectories.score[second]
    worse = jnp.where(first_better, second, first)
    better = jnp.where(first_better, first, second)
    room = jnp.maximum(trajectories.lengths - snippet_length, 0) + 1  # possible starts
    uniform = jax.random.uniform(start_key, (2, num_pairs))
    starts = jnp.floor(uniform * room[jnp.stack([worse, better])]).astype(jnp.int32)
    informative = trajectories.score[first] != trajectories.score[second]
    real = (trajectories.lengths[first] > 0) & (trajectories.lengths[second] > 0)  # not padding
    weight = (informative & real).astype(jnp.float32)
    return SnippetPairs(worse, starts[0], better, starts[1], weight)


def pad(trajectories: Trajectories, num: int, steps: int) -> Trajectories:
    """``trajectories`` padded to ``num`` trajectories of ``steps`` steps (added trajectories
    have length 0 and are never in a weighted pair)."""
    k, t = trajectories.lengths.shape[0], trajectories.observations.shape[1]

    def padded(x, *fill):
        return jnp.pad(x, [(0, num - k), *fill])

    return Trajectories(
        observations=padded(trajectories.observations, (0, steps - t), (0, 0)),
        actions=padded(trajectories.actions, (0, steps - t), (0, 0)),
        lengths=padded(trajectories.lengths),
        score=padded(trajectories.score),
    )


def select(condition, on_true: Trajectories, on_false: Trajectories) -> Trajectories:
    """One of two sets of trajectories by a traced ``condition`` (both padded to one shape),
    so cells of a grid can rank different trajectories."""
    num = max(on_true.lengths.shape[0], on_false.lengths.shape[0])
    steps = max(on_true.observations.shape[1], on_false.observations.shape[1])
    a, b = pad(on_true, num, steps), pad(on_false, num, steps)
    return jax.tree.map(lambda x, y: jnp.where(condition, x, y), a, b)


def snippets(
    features: jax.Array, lengths: jax.Array, index: jax.Array, start: jax.Array, length: int
):
    """The snippets [start, start + length) of trajectories ``index`` (int[P] each) of
    ``features`` float[K, T, F]: float[P, length, F] and bool[P, length] (real steps, not
    padding or beyond the end)."""
    steps = start[:, None] + jnp.arange(length)
    inside = steps < jnp.minimum(lengths[index], features.shape[1])[:, None]
    return features[index[:, None], jnp.minimum(steps, features.shape[1] - 1)], inside


def bradley_terry_loss(worse_sums: jax.Array, better_sums: jax.Array, weight: jax.Array):
    """Mean over weighted pairs of -log P(better wins) = softplus(R_worse - R_better).

    worse_sums, better_sums, weight: float[P]. Returns ``(loss, metrics)``.
    """
    chex.assert_equal_shape([worse_sums, better_sums, weight])
    total = jnp.maximum(weight.sum(), 1e-8)
    loss = jnp.sum(weight * jax.nn.softplus(worse_sums - better_sums)) / total
    accuracy = jnp.sum(weight * (better_sums > worse_sums)) / total
    return loss, {"ranking/loss": loss, "ranking/accuracy": accuracy}


def ranking_loss(
    reward_fn, features: jax.Array, trajectories: Trajectories, pairs: SnippetPairs, length: int
):
    """The Bradley-Terry loss of ``reward_fn`` (float[..., F] -> float[...]) summed over the
    ``pairs`` of snippets of per-step ``features`` float[K, T, F]. The reward is computed on
    the snippets' steps only, so its cost does not grow with the trajectories' length."""

    def sums(index, start):
        inputs, inside = snippets(features, trajectories.lengths, index, start, length)
        return jnp.where(inside, reward_fn(inputs), 0.0).sum(axis=1)

    worse = sums(pairs.worse, pairs.worse_start)
    better = sums(pairs.better, pairs.better_start)
    return bradley_terry_loss(worse, better, pairs.weight)


class StateReward:
    """A reward network r(s): a tanh MLP of the observation, without an output bias.

    Rankings of equal-length snippets do not change when a constant is added to r, so an
    output bias would get no gradient but float noise, which Adam scales up to full steps
    (and the learned reward would then differ in its offset from one program to the next).
    """

    def __init__(self, hidden_sizes):
        self.network = MLP(tuple(hidden_sizes), 1, output_bias=False)

    def init(self, key, observation_size: int):
        return self.network.init(key, jnp.zeros((observation_size,)))

    def __call__(self, params, observations: jax.Array) -> jax.Array:
        return self.network.apply(params, observations)[..., 0]


def train_ranking_reward(config: RankingConfig, trajectories: Trajectories, key: jax.Array):
    """Fits ``StateReward`` to the rankings of ``trajectories`` (T-REX's reward learning).

    Returns ``(params, metrics)``, metrics float[num_steps] each (loss and pair accuracy).
    """
    reward = StateReward(config.hidden_sizes)
    init_key, train_key = jax.random.split(key)
    params = reward.init(init_key, trajectories.observations.shape[-1])

    def loss_fn(params, key):
        pairs = sample_pairs(key, trajectories, config.pairs_per_step, config.snippet_length)
        return ranking_loss(
            lambda observations: reward(params, observations), trajectories.observations,
            trajectories, pairs, config.snippet_length,
        )  # fmt: skip

    keys = jax.random.split(train_key, config.num_steps)
    return fit_with_adam(loss_fn, params, config.learning_rate, keys)


def noisy_rollouts(env, act_mean, config: RankingConfig, key: jax.Array) -> Trajectories:
    """D-REX's ranked trajectories: ``rollouts_per_level`` episodes of ``act_mean(obs)`` with
    epsilon-greedy noise per level (with probability epsilon a uniform random action), scored
    by minus the noise level."""
    from pngail_jax.demos.generate import rollout_episodes

    low, high = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
    levels = jnp.repeat(jnp.asarray(config.noise_levels, jnp.float32), config.rollouts_per_level)

    def episode(level, episode_key):
        def act(obs, step_key):
            explore_key, action_key = jax.random.split(step_key)
            random_action = jax.random.uniform(action_key, low.shape, minval=low, maxval=high)
            greedy = jnp.clip(act_mean(obs), low, high)
            return jnp.where(jax.random.uniform(explore_key) < level, random_action, greedy)

        return jax.tree.map(lambda x: x[0], rollout_episodes(env, act, episode_key[None]))

    episodes = jax.vmap(episode)(levels, jax.random.split(key, levels.shape[0]))
    return Trajectories(
        observations=episodes.observations,
        actions=episodes.actions,
        lengths=episodes.valid.sum(axis=1).astype(jnp.int32),
        score=-levels,
    )


def cail_outer_loss(
    log_confidence, inner_loss, params, learning_rate, reward_of, features, trajectories, pairs,
    length,
):  # fmt: skip
    """CAIL's outer objective: the ranking loss of the reward after one gradient step.

    ``inner_loss(params, log_confidence)`` is the confidence-weighted adversarial loss;
    ``params - learning_rate * grad inner_loss`` is the lookahead, ``reward_of(params, x)`` its
    reward of per-step ``features`` x, and the Bradley-Terry loss of that reward on ``pairs``
    of snippets of ``trajectories`` (``ranking_loss``) is returned as ``(loss, metrics)``.
    Differentiate it with respect to ``log_confidence`` for CAIL's outer step (through the
    lookahead).
    """
    grads = jax.grad(inner_loss)(params, log_confidence)
    lookahead = jax.tree.map(lambda p, g: p - learning_rate * g, params, grads)
    return ranking_loss(lambda x: reward_of(lookahead, x), features, trajectories, pairs, length)
