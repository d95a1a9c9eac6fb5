"""Rewards learned from ranked trajectories (T-REX, D-REX).

T-REX (Brown et al., 2019) fits a state reward r(s) so that of two trajectory snippets the
better-ranked one has the larger summed reward, with the Bradley-Terry likelihood

    P(snippet j better than snippet i) = exp(R_j) / (exp(R_i) + exp(R_j)),   R = sum_t r(s_t),

and then runs RL on r. D-REX (Brown et al., 2020) makes its own rankings: rollouts of a
behaviour-cloned policy with epsilon-greedy noise, less noise ranked better (CAIL's ranking
loss is in ``pngail_jax.adversarial.cail``). Here the rankings of the demonstrations are their
confidences; a learner sees those of an ``eligible`` subset of the trajectories only
(``sample_pairs``).

T-REX and D-REX run with the settings of the CAIL codebase (Stanford-ILIAD/
Confidence-Aware-Imitation-Learning), whose runs the paper reports: ``RankingConfig()`` is
T-REX's reward fit, ``DrexConfig()`` D-REX's cloned policy, noisy rollouts and reward fit.

Every function is pure and jittable; ``Trajectories`` are padded to one length, so a grid can
``vmap`` over seeds and methods. ``RankingPhase`` is their phase in the adversarial trainer.
"""

from __future__ import annotations

import dataclasses

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.adversarial.bc import DeterministicBCConfig, cloned_actions, train_deterministic_bc
from pngail_jax.adversarial.phase import Phase, PhaseContext
from pngail_jax.fitting import fit_with_adam, squared_norm
from pngail_jax.networks import ReluMLP


@dataclasses.dataclass(frozen=True)
class RankingConfig:
    """Static settings of one reward fit from rankings. The defaults are T-REX's in the CAIL
    codebase (``cail/algo/trex.py``); ``DrexConfig().ranking`` holds D-REX's."""

    num_steps: int = 10_000  # Adam steps of each network
    pairs_per_step: int = 64
    snippet_length: int = 40  # steps summed per snippet
    # True (T-REX): every snippet has exactly ``snippet_length`` steps, so trajectories
    # shorter than that are never drawn. False (D-REX): a shorter trajectory is one whole
    # snippet.
    skip_short_trajectories: bool = True
    learning_rate: float = 3e-4
    l2_coef: float = 0.01  # loss += l2_coef ||theta||^2, every parameter
    hidden_sizes: tuple[int, ...] = (256, 256)
    num_members: int = 1  # an ensemble, each with its own initialisation and pairs
    label_flip_probability: float = 0.0  # each step's pairs swapped with this probability
    min_score_margin: float = 0.0  # pairs only between scores at least this far apart
    # None: pairs drawn afresh every step. N: each member draws one set of N pairs first, and
    # each step draws ``pairs_per_step`` of them without replacement.
    num_dataset_pairs: int | None = None

    def __post_init__(self):
        for name in ("num_steps", "pairs_per_step", "snippet_length", "num_members"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"RankingConfig.{name} must be a positive integer, got {value!r}")
        if not 0 <= self.label_flip_probability <= 1:
            raise ValueError(
                "RankingConfig.label_flip_probability must lie in [0, 1], "
                f"got {self.label_flip_probability!r}"
            )
        if not (self.l2_coef >= 0 and self.min_score_margin >= 0):
            raise ValueError("RankingConfig.l2_coef and min_score_margin must be >= 0")
        if self.num_dataset_pairs is not None and not (
            isinstance(self.num_dataset_pairs, int)
            and self.num_dataset_pairs >= self.pairs_per_step
        ):
            raise ValueError(
                "RankingConfig.num_dataset_pairs must be None or an integer >= pairs_per_step "
                f"({self.pairs_per_step}), got {self.num_dataset_pairs!r}"
            )


@dataclasses.dataclass(frozen=True)
class DrexConfig:
    """D-REX's static settings, with the CAIL codebase's values (``cail/algo/drex.py``,
    ``NoisePreferenceDataset``): its cloned policy, the epsilon-greedy noise levels of that
    policy's rollouts (0.00, 0.05, ..., 0.95) and rollouts per level, and its reward fit."""

    bc: DeterministicBCConfig = DeterministicBCConfig()
    noise_levels: tuple[float, ...] = tuple(round(0.05 * level, 2) for level in range(20))
    rollouts_per_level: int = 5
    ranking: RankingConfig = RankingConfig(
        snippet_length=50,
        skip_short_trajectories=False,
        learning_rate=1e-4,
        num_members=3,
        label_flip_probability=0.1,
        min_score_margin=0.3,
        # Their 5,000 pairs per network, of which the 80% training split is read (the
        # validation 20% never is).
        num_dataset_pairs=4_000,
    )

    def __post_init__(self):
        value = self.rollouts_per_level
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ValueError(
                f"DrexConfig.rollouts_per_level must be a positive integer, got {value!r}"
            )
        if not self.noise_levels or not all(0 <= level <= 1 for level in self.noise_levels):
            raise ValueError(f"DrexConfig.noise_levels must lie in [0, 1], got {self.noise_levels}")


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
    key: jax.Array,
    trajectories: Trajectories,
    num_pairs: int,
    snippet_length: int,
    eligible: jax.Array | None = None,
    min_score_margin: float = 0.0,
) -> SnippetPairs:
    """``num_pairs`` ordered pairs of trajectories drawn uniformly, with replacement, among the
    pairs of ``eligible`` ones (bool[K], the trajectories whose ranking a learner may see;
    None: every one) whose scores are at least ``min_score_margin`` apart, each pair then
    ordered by score; each snippet starts uniformly where ``snippet_length`` steps fit (at 0
    in a shorter trajectory).

    With margin 0 this is two independent uniform draws among the eligible trajectories (a
    trajectory may meet itself); a pair of equal scores gets weight 0. Padding trajectories
    (length 0) are never drawn; when no pair is allowed every weight is 0.
    """
    first_key, second_key, start_key = jax.random.split(key, 3)
    num = trajectories.lengths.shape[0]
    score = trajectories.score
    drawable = trajectories.lengths > 0
    if eligible is not None:
        chex.assert_shape(eligible, (num,))
        drawable = drawable & eligible
    # The tolerance keeps nominal margins (0.9 - 0.6 >= 0.3) true in float32.
    apart = jnp.abs(score[:, None] - score[None, :]) >= min_score_margin - 1e-6
    allowed = drawable[:, None] & drawable[None, :] & apart  # bool[K, K]
    partners = allowed.sum(axis=1)
    # First in proportion to its number of partners, then one of them uniformly: every
    # allowed ordered pair is equally likely.
    first = jax.random.choice(
        first_key, num, (num_pairs,), p=partners / jnp.maximum(partners.sum(), 1)
    )

    def partner(key, row):  # row: bool[K], the partners of one first trajectory
        return jax.random.choice(key, num, p=row / jnp.maximum(row.sum(), 1))

    second = jax.vmap(partner)(jax.random.split(second_key, num_pairs), allowed[first])
    first_better = score[first] > score[second]
    worse = jnp.where(first_better, second, first)
    better = jnp.where(first_better, first, second)
    room = jnp.maximum(trajectories.lengths - snippet_length, 0) + 1  # possible starts
    uniform = jax.random.uniform(start_key, (2, num_pairs))
    starts = jnp.floor(uniform * room[jnp.stack([worse, better])]).astype(jnp.int32)
    informative = (score[first] != score[second]) & allowed[first, second]
    return SnippetPairs(worse, starts[0], better, starts[1], informative.astype(jnp.float32))


def flip_labels(key: jax.Array, pairs: SnippetPairs, probability) -> SnippetPairs:
    """``pairs`` with each pair's worse and better snippets swapped with ``probability``
    (D-REX's label noise, drawn afresh for every batch)."""
    flip = jax.random.bernoulli(key, probability, pairs.worse.shape)

    def swapped(a, b):
        return jnp.where(flip, b, a)

    return pairs.replace(
        worse=swapped(pairs.worse, pairs.better),
        worse_start=swapped(pairs.worse_start, pairs.better_start),
        better=swapped(pairs.better, pairs.worse),
        better_start=swapped(pairs.better_start, pairs.worse_start),
    )


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


class RankingReward:
    """T-REX's and D-REX's reward r(s): the CAIL codebase's ``StateFunction`` (a ReLU MLP of
    the observation, orthogonal initialisation, ``networks.ReluMLP``) without its output
    bias. Rankings of equal-length snippets do not change when a constant is added to r, so
    that bias would get no gradient but float noise, which Adam scales up to full steps (and
    the learned reward would then differ in its offset from one program to the next; with the
    L2 term it would only decay from its initial 0). An ensemble's parameters carry a leading
    member axis [M]."""

    def __init__(self, hidden_sizes):
        self.network = ReluMLP(tuple(hidden_sizes), 1, output_bias=False)

    def init(self, key, observation_size: int):
        """One network's parameters."""
        return self.network.init(key, jnp.zeros((observation_size,)))

    def __call__(self, params, observations: jax.Array) -> jax.Array:
        """One network's r: float[...] for observations float[..., O]."""
        return self.network.apply(params, observations)[..., 0]

    def ensemble(self, params, observations: jax.Array) -> jax.Array:
        """The mean over the members (params with a leading axis [M]) of r: float[...]."""
        return jax.vmap(self, (0, None))(params, observations).mean(axis=0)


def reward_loss(
    reward: RankingReward, params, trajectories: Trajectories, pairs: SnippetPairs, length: int,
    l2_coef,
):  # fmt: skip
    """The Bradley-Terry (two-way cross-entropy) loss of one network's r on ``pairs`` of
    snippets of ``length`` steps of the trajectories' observations, plus
    ``l2_coef ||params||^2``. Returns ``(loss, metrics)``."""
    loss, metrics = ranking_loss(
        lambda observations: reward(params, observations), trajectories.observations,
        trajectories, pairs, length,
    )  # fmt: skip
    penalty = l2_coef * squared_norm(params)
    return loss + penalty, {**metrics, "ranking/l2": penalty}


def drawable_trajectories(
    config: RankingConfig, trajectories: Trajectories, eligible: jax.Array | None
) -> jax.Array | None:
    """The trajectories a fit draws pairs from: ``eligible`` (bool[K]; None: all) and, with
    ``config.skip_short_trajectories`` (T-REX), at least ``snippet_length`` steps long."""
    if not config.skip_short_trajectories:
        return eligible
    long_enough = trajectories.lengths >= config.snippet_length
    return long_enough if eligible is None else eligible & long_enough


def train_ranking_reward(
    config: RankingConfig,
    trajectories: Trajectories,
    key: jax.Array,
    eligible: jax.Array | None = None,
):
    """Fits ``config.num_members`` ``RankingReward`` networks, each on its own pairs, to the
    rankings of ``trajectories`` (T-REX's and D-REX's reward learning). ``eligible`` bool[K]:
    the trajectories whose ranking the learner may see (None: all); pairs are drawn only
    among them (``sample_pairs``).

    Returns ``(params, metrics)``: params with a leading member axis [M]
    (``RankingReward.ensemble`` reads them), metrics float[M, num_steps] each.
    """
    reward = RankingReward(config.hidden_sizes)
    length = config.snippet_length
    eligible = drawable_trajectories(config, trajectories, eligible)

    def draw(key, num_pairs):
        return sample_pairs(key, trajectories, num_pairs, length, eligible, config.min_score_margin)

    def fit(key):
        init_key, dataset_key, train_key = jax.random.split(key, 3)
        params = reward.init(init_key, trajectories.observations.shape[-1])
        fixed = config.num_dataset_pairs is not None
        dataset = draw(dataset_key, config.num_dataset_pairs) if fixed else None

        def loss_fn(params, key):
            pairs_key, flip_key = jax.random.split(key)
            if not fixed:
                pairs = draw(pairs_key, config.pairs_per_step)
            else:
                rows = jax.random.choice(
                    pairs_key, config.num_dataset_pairs, (config.pairs_per_step,), replace=False
                )
                pairs = jax.tree.map(lambda x: x[rows], dataset)
            pairs = flip_labels(flip_key, pairs, config.label_flip_probability)
            return reward_loss(reward, params, trajectories, pairs, length, config.l2_coef)

        keys = jax.random.split(train_key, config.num_steps)
        return fit_with_adam(loss_fn, params, config.learning_rate, keys)

    return jax.vmap(fit)(jax.random.split(key, config.num_members))


def noisy_rollouts(env, act, config: DrexConfig, key: jax.Array) -> Trajectories:
    """D-REX's ranked trajectories: ``config.rollouts_per_level`` episodes per noise level of
    ``act(obs) -> action`` (the cloned policy, within the bounds) with epsilon-greedy noise
    (each step, with probability epsilon, an action uniform within the bounds), scored by
    minus the noise level."""
    from pngail_jax.demos.generate import rollout_episodes

    low, high = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
    levels = jnp.repeat(jnp.asarray(config.noise_levels, jnp.float32), config.rollouts_per_level)

    def episode(level, episode_key):
        def noisy_act(obs, step_key):
            explore_key, action_key = jax.random.split(step_key)
            random_action = jax.random.uniform(action_key, low.shape, minval=low, maxval=high)
            return jnp.where(jax.random.uniform(explore_key) < level, random_action, act(obs))

        return jax.tree.map(lambda x: x[0], rollout_episodes(env, noisy_act, episode_key[None]))

    episodes = jax.vmap(episode)(levels, jax.random.split(key, levels.shape[0]))
    return Trajectories(
        observations=episodes.observations,
        actions=episodes.actions,
        lengths=episodes.valid.sum(axis=1).astype(jnp.int32),
        score=-levels,
    )


class RankingPhase(Phase):
    """Rewards learned from rankings in the adversarial trainer, one ensemble per compiled
    name: T-REX's (``demo_rankings``: the ``ranked`` demonstration trajectories) and D-REX's
    (``noise_rankings``: noisy rollouts of its own cloned policy). The policy's reward gains
    ``spec.ranking_reward_coef`` times D-REX's ensemble mean where ``spec.noise_rankings_coef``
    is 1, T-REX's where it is 0 (in a grid with both, every cell fits both)."""

    def __init__(self, names: tuple[str, ...], config: RankingConfig, drex: DrexConfig):
        self.names, self.config, self.drex = names, config, drex
        self.ranks_demonstrations = "demo_rankings" in names
        self.rewards = {
            "demo_rankings": RankingReward(config.hidden_sizes),
            "noise_rankings": RankingReward(drex.ranking.hidden_sizes),
        }

    def init(self, context: PhaseContext, spec, inputs, confidence, learner_state, keys, ranked):
        trex_key, drex_key = jax.random.split(keys.reward)
        params = {}
        if "demo_rankings" in self.names:
            params["demo_rankings"], _ = train_ranking_reward(
                self.config, context.trajectories, trex_key, eligible=ranked
            )
        if "noise_rankings" in self.names:
            trajectories = self.noisy_rollouts(context, inputs, keys.noise)
            params["noise_rankings"], _ = train_ranking_reward(
                self.drex.ranking, trajectories, drex_key
            )
        return {"ranking_reward_params": params}, learner_state

    def noisy_rollouts(self, context: PhaseContext, inputs, key) -> Trajectories:
        """D-REX's ranked trajectories: its deterministic policy cloned from the split's
        ``inputs`` float[M, O + A] (not the learner's policy of ``bc``), rolled out at each
        noise level."""
        size, drex = context.env.observation_size, self.drex
        low, high = context.action_bounds
        bc_key, rollout_key = jax.random.split(key)
        params, _ = train_deterministic_bc(
            drex.bc, inputs[:, :size], inputs[:, size:], low, high, bc_key
        )

        def act(obs):
            return cloned_actions(drex.bc, params, obs, low, high)

        return noisy_rollouts(context.env, act, drex, rollout_key)

    def reward(self, context: PhaseContext, spec, state, transitions, batch, key):
        weight = {
            "demo_rankings": 1 - spec.noise_rankings_coef,
            "noise_rankings": spec.noise_rankings_coef,
        }
        term = sum(
            weight[name] * self.rewards[name].ensemble(params, batch.agent_obs)
            for name, params in state.ranking_reward_params.items()
        )
        return spec.ranking_reward_coef * term, {}, {}
