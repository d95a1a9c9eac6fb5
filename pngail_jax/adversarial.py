"""Adversarial imitation as one pure program: ``AdversarialTrainer(config, env, demos)``.

``trainer.train(hyperparams, spec, key)`` runs, for one method (``spec``, data) and one seed:

1. the split of the demonstrations into D_c (labelled) and D_u, and the confidence classifier
   where the method needs one (``spec.classifier_coef``), giving a confidence r per row;
2. ``num_iterations`` of: a rollout; the policy reward ``-log sigmoid(z)`` from the
   discriminator *before* this iteration's update; one Adam step of the discriminator on the
   agent batch and as many demonstration rows drawn with replacement; one update of the
   policy learner (TRPO, the paper's, or PPO: ``AdversarialConfig.learner``).

The discriminator (and every other learned function that compares the agent with the
demonstrations: WGAIL's weights, behaviour cloning, CAIL's rankings) sees agent and
demonstration actions in one space, the action the environment applies: both clipped to the
action bounds. The reference compares the policy's unclipped outputs on both sides (and, on
Pendulum, full-scale agent torques with half-scale demonstrations); we compare what acts on the
physics, so no feature the environment ignores (|a| beyond the bound) separates the two.

``train`` is ``init`` followed by ``run_blocks``, so a host loop can run the same computation
in chunks (``pngail_jax.grid``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from pngail_jax import cail, envs, firl, ranking
from pngail_jax.bc import BCConfig, cloned_actions, train_bc, train_deterministic_bc
from pngail_jax.confidence import ClassifierConfig, confidence_errors, train_classifier
from pngail_jax.demos import DemonstrationError, Demonstrations, make_split
from pngail_jax.firl import FirlState
from pngail_jax.fitting import tree_where
from pngail_jax.losses import ConfidenceStats, discriminator_loss, policy_reward
from pngail_jax.methods import PHASES, MethodSpec, required_phases, resolve
from pngail_jax.networks import ClampedStateReward, Discriminator, ResidualDiscriminator
from pngail_jax.rl.learners import check_learner, learner_hyperparams, make_learner
from pngail_jax.rl.ppo import PPOConfig, PPOHyperparams, PPOState
from pngail_jax.rl.train import TRPOConfig, TRPOHyperparams, TRPOState, run_evaluated_blocks


@dataclasses.dataclass(frozen=True)
class AdversarialConfig:
    """Static settings (shapes, counts, schedules) of an adversarial run."""

    # The rollout's shape and the policy and value networks (both learners), TRPO's settings.
    trpo: TRPOConfig = TRPOConfig()
    # The policy learner, "trpo" (the paper's) or "ppo" (``rl.learners``), and PPO's settings.
    learner: str = "trpo"
    ppo: PPOConfig = PPOConfig()
    classifier: ClassifierConfig = ClassifierConfig()
    # Rows per split (the paper's n_c + n_u); None = every demonstration row.
    num_demos: int | None = None
    discriminator_hidden_sizes: tuple[int, ...] = (100, 100)
    # WGAIL refreshes its weights at iterations every, 2 every, ..., until (w = 1 before).
    wgail_refresh_every: int = 50
    wgail_refresh_until: int = 400
    # The appendix baselines' training phases this trainer compiles (``methods.PHASES``;
    # ``methods.required_phases(names)``); none for the paper's seven.
    phases: tuple[str, ...] = ()
    # D-REX's cloned policy, noisy rollouts and reward fit; ``ranking`` is T-REX's reward fit.
    drex: ranking.DrexConfig = ranking.DrexConfig()
    ranking: ranking.RankingConfig = ranking.RankingConfig()
    bc: BCConfig = BCConfig()
    cail: cail.CAILConfig = cail.CAILConfig()
    firl: firl.FirlConfig = firl.FirlConfig()
    # Compile the discriminator's gradient penalty (MethodSpec.gradient_penalty_coef): only
    # grids with a cell that uses it pay for its second pass through the discriminator.
    gradient_penalty: bool = False

    def __post_init__(self):
        check_learner(self.learner)
        if self.learner == "ppo":
            self.ppo.check_batch(self.trpo)
        unknown = [phase for phase in self.phases if phase not in PHASES]
        if unknown or len(set(self.phases)) != len(self.phases):
            raise ValueError(
                f"AdversarialConfig.phases must be distinct names from {PHASES}, "
                f"got {self.phases!r}"
            )
        if self.num_demos is not None and (
            not isinstance(self.num_demos, int) or self.num_demos < 2
        ):
            raise ValueError(
                "AdversarialConfig.num_demos must be an integer >= 2 or None, "
                f"got {self.num_demos!r}"
            )
        for name in ("wgail_refresh_every", "wgail_refresh_until"):
            if not isinstance(getattr(self, name), int) or getattr(self, name) < 1:
                raise ValueError(f"AdversarialConfig.{name} must be a positive integer")


@struct.dataclass
class AdversarialHyperparams:
    """Per-cell values a grid may vary (pytree leaves). ``trpo`` holds the policy learner's
    hyperparameters, TRPO's or PPO's."""

    trpo: TRPOHyperparams | PPOHyperparams
    discriminator_learning_rate: jax.Array
    label_ratio: jax.Array  # fraction of the split that is labelled (D_c)
    noise_std: jax.Array  # confidence noise: r <- clip(r + N(0, noise_std^2), 0, 1)

    @classmethod
    def create(
        cls,
        label_ratio=0.2,
        noise_std=0.0,
        discriminator_learning_rate=1e-3,
        learner="trpo",
        **learner_values,
    ) -> AdversarialHyperparams:
        """The values of one cell; ``learner_values`` are the learner's hyperparameters
        (``TRPOHyperparams`` or, with ``learner="ppo"``, ``PPOHyperparams``)."""
        if not 0 < label_ratio < 1:
            raise ValueError(f"label_ratio must be in (0, 1), got {label_ratio!r}")
        if not noise_std >= 0:
            raise ValueError(f"noise_std must be >= 0, got {noise_std!r}")
        if not discriminator_learning_rate > 0:
            raise ValueError(
                f"discriminator_learning_rate must be positive, got {discriminator_learning_rate!r}"
            )
        return cls(
            trpo=learner_hyperparams(learner, **learner_values),
            discriminator_learning_rate=jnp.asarray(discriminator_learning_rate, jnp.float32),
            label_ratio=jnp.asarray(label_ratio, jnp.float32),
            noise_std=jnp.asarray(noise_std, jnp.float32),
        )


@struct.dataclass
class TrainState:
    trpo: TRPOState | PPOState  # the policy learner's state
    discriminator_params: dict
    discriminator_optimizer_state: optax.OptState
    demo_rows: jax.Array  # int32[M]: the split's rows of the demonstration set
    confidence: jax.Array  # float32[M]: r the losses use (given on D_c, classifier on D_u)
    labelled: jax.Array  # bool[M]: D_c
    importance_weights: jax.Array  # float32[M]: WGAIL's w (1 until its first refresh)
    stats: ConfidenceStats
    iteration: jax.Array  # int32[]
    eval_keys: jax.Array  # key[num_eval_episodes], the same every evaluation
    key: jax.Array
    # The appendix baselines' state; None when their phase is not compiled.
    # T-REX's / D-REX's learned r(s): {phase: an ensemble's params, leading axis [M]}.
    ranking_reward_params: dict | None = None
    firl: FirlState | None = None
    cail_confidence: jax.Array | None = None  # float32[M]: CAIL's beta per split row
    # bool[K]: the demonstration trajectories whose ranking T-REX and CAIL may see (a share
    # ``label_ratio`` of them, at least 2, drawn per seed: the label information PN-GAIL gets).
    ranked_trajectories: jax.Array | None = None


class DiscriminatorBatch(NamedTuple):
    """One iteration's discriminator batch: the rollout's B rows and B split rows."""

    agent_obs: jax.Array  # float[B, O]
    agent_inputs: jax.Array  # float[B, O + A], actions clipped to the bounds
    rows: jax.Array  # int[B], indices into the split
    demo_inputs: jax.Array  # float[B, O + A]


class AdversarialTrainer:
    """Adversarial imitation of ``demos`` in ``env``, one method (a ``MethodSpec``) per call.

    The trainer interface shared with ``pngail_jax.rl.TRPOTrainer`` (and used by
    ``pngail_jax.grid.Grid``); the cell inputs here are ``(hyperparams, spec)``:

    - ``init(hyperparams, spec, key) -> (state, init_metrics)``: the split, the classifier
      phase and the initial networks; ``init_metrics`` holds ``confidence/mae`` and
      ``confidence/rmse`` (float[], on D_u against the noise-free confidences; NaN when the
      demonstrations carry no confidences);
    - ``run_blocks(hyperparams, spec, state, num_blocks) -> (state, metrics)``: ``num_blocks``
      (static) blocks of ``eval_every`` iterations, metrics float[num_blocks * eval_every]
      (``eval/return`` NaN except at each block's end);
    - ``train(hyperparams, spec, key)``: both, for the configured number of iterations.

    Demonstrations without confidences serve only methods that read none (GAIL, WGAIL):
    ``has_confidence`` says which case this is, and ``check_methods`` refuses the others. Only
    rows the demonstrations' ``labelled`` mask allows are labelled (``make_split``);
    ``check_label_ratios`` refuses ratios that ask for more labelled rows than it allows.
    """

    def __init__(self, config: AdversarialConfig, env: envs.Env, demos: Demonstrations):
        demos.check_env(env)
        num_demos = demos.num_rows if config.num_demos is None else config.num_demos
        if num_demos > demos.num_rows:
            raise DemonstrationError(
                f"num_demos={num_demos} but the demonstrations have only {demos.num_rows} rows"
            )
        self.config = config
        self.env = env
        self.num_demos = num_demos
        self.has_confidence = demos.confidence is not None
        # The policy learner (named ``trpo`` whichever it is, as its state's field).
        self.trpo = make_learner(config.learner, config.trpo, env, config.ppo)
        self.discriminator = Discriminator(config.discriminator_hidden_sizes)
        self.optimizer = optax.scale_by_adam()
        # One action space on both sides of every learned comparison with the agent (the
        # discriminator, WGAIL's weights, BC, CAIL's rankings): the action the environment
        # applies. The agent's actions are clipped to the bounds in ``_iteration``, the
        # demonstrations' here (the authors' MuJoCo files store unclipped policy actions, and
        # a discriminator could otherwise tell them apart by |a| > 1 alone). The confidence
        # classifier compares demonstrations only with each other and reads the file's rows,
        # as the authors' classifier does.
        low, high = np.asarray(env.action_low), np.asarray(env.action_high)
        self.num_clipped_rows = int(demos.rows_beyond(low, high).sum())
        applied = demos.clipped(low, high)
        self._demo_inputs = jnp.asarray(applied.inputs)
        self._classifier_inputs = jnp.asarray(demos.inputs)
        # Without confidences every row gets r = 1; no method that reads r may run then.
        self._confidence = jnp.asarray(
            demos.confidence if self.has_confidence else np.ones(demos.num_rows, np.float32)
        )
        self._action_bounds = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
        # The rows whose confidence a learner may see (the file's ``labelled`` mask; None: all).
        has_mask = self.has_confidence and demos.labelled is not None
        self._allowed = jnp.asarray(demos.labelled) if has_mask else None
        self.num_allowed = int(demos.labelled.sum()) if has_mask else demos.num_rows
        # Whole trajectories ranked by their given confidence (T-REX, CAIL), when the set has
        # trajectory ids; each row's trajectory index.
        self.trajectories = self._row_trajectory = None
        if demos.trajectory_ids is not None and self.has_confidence:
            self.trajectories, self._row_trajectory = ranking.trajectories_of(
                applied.observations, applied.actions, demos.trajectory_ids, demos.confidence
            )
        # The rewards learned from rankings, by the phase that fits them.
        self.ranking_rewards = {
            "demo_rankings": ranking.RankingReward(config.ranking.hidden_sizes),
            "noise_rankings": ranking.RankingReward(config.drex.ranking.hidden_sizes),
        }
        self._init_firl(config.firl, demos)

    def _init_firl(self, config: firl.FirlConfig, demos: Demonstrations) -> None:
        """f-IRL's networks, optimisers and the source of its demonstration segments: the
        set's trajectories when it has trajectory ids, else (None) consecutive split rows."""
        self.firl_discriminator = ResidualDiscriminator(
            config.discriminator_hidden_size, config.discriminator_residual_blocks,
            config.clamp_magnitude,
        )  # fmt: skip
        self.firl_reward = ClampedStateReward(config.reward_hidden_sizes, config.clamp_magnitude)
        self.firl_discriminator_optimizer = firl.adam_with_l2(
            config.discriminator_learning_rate, config.discriminator_weight_decay
        )
        self.firl_reward_optimizer = firl.adam_with_l2(
            config.reward_learning_rate, config.reward_weight_decay
        )
        self._firl_segments = None
        if "firl" in self.config.phases and demos.trajectory_ids is not None:
            self._firl_segments = firl.SegmentSource.of_trajectories(demos.trajectory_ids)

    @property
    def demo_inputs(self) -> jax.Array:
        """float[N, O + A]: every demonstration row as the discriminator sees it (actions
        clipped to the action bounds)."""
        return self._demo_inputs

    def check_label_ratios(self, label_ratios) -> None:
        """Raises ``DemonstrationError`` when the demonstrations' ``labelled`` mask allows
        fewer rows than the largest ratio labels, ``round(label_ratio * num_demos)``, and
        ``ValueError`` when the smallest ratio needs a wider unlabelled classifier batch than
        the config compiles; call it on the host before building a grid (the split itself
        labels at most the allowed rows)."""
        largest = max(float(ratio) for ratio in label_ratios)
        requested = round(largest * self.num_demos)
        if self.has_confidence and requested > self.num_allowed:
            raise DemonstrationError(
                f"label ratio {largest:g} of {self.num_demos} rows asks for {requested} labelled "
                f"rows, but the demonstrations' labelled mask allows only {self.num_allowed}"
            )
        classifier = self.config.classifier
        smallest = min(float(ratio) for ratio in label_ratios)
        num_labelled = max(round(smallest * self.num_demos), 1)
        needed = classifier.unlabelled_rows_per_step(self.num_demos, num_labelled)
        if needed > classifier.unlabelled_batch_width:
            raise ValueError(
                f"label ratio {smallest:g} of {self.num_demos} rows needs {needed} unlabelled "
                "rows per classifier step (n_u // n_c), more than ClassifierConfig's "
                f"max_unlabelled_batch_size {classifier.max_unlabelled_batch_size}: raise it"
            )

    def check_methods(self, methods) -> None:
        """Raises ``DemonstrationError`` naming the methods that need confidences the
        demonstrations do not carry."""
        readers = [name for name in methods if resolve(name).confidence_source != "none"]
        if not self.has_confidence and readers:
            raise DemonstrationError(
                f"the demonstrations carry no confidences, which {', '.join(readers)} read; "
                "give a confidence file, or run only methods that read none (gail, wgail)"
            )
        missing = [p for p in required_phases(methods) if p not in self.config.phases]
        if missing:
            raise ValueError(
                f"methods {list(methods)} need the training phase(s) {missing}, which this "
                "trainer does not compile: AdversarialConfig(phases=required_phases(methods))"
            )
        penalised = [
            name for name in methods if resolve(name).coefficients.get("gradient_penalty_coef")
        ]
        if penalised and not self.config.gradient_penalty:
            raise ValueError(
                f"{', '.join(penalised)} use a gradient penalty, which this trainer does not "
                "compile: AdversarialConfig(gradient_penalty=True)"
            )
        rankers = [name for name in methods if resolve(name).confidence_source == "rankings"]
        if rankers and self.trajectories is None:
            raise DemonstrationError(
                f"{', '.join(rankers)} rank whole trajectories, but these demonstrations have "
                "no trajectory ids (the authors' MuJoCo files are rows, not trajectories; "
                "made sets and the authors' Pendulum file have them)"
            )
        if rankers and len(np.unique(np.asarray(self.trajectories.score))) < 2:
            raise DemonstrationError(
                f"{', '.join(rankers)} need trajectories of at least two confidences to rank"
            )
        length = self.config.ranking.snippet_length
        if (
            "demo_rankings" in required_phases(methods)
            and self.config.ranking.skip_short_trajectories
        ):
            long_enough = np.asarray(self.trajectories.lengths) >= length
            if len(np.unique(np.asarray(self.trajectories.score)[long_enough])) < 2:
                raise DemonstrationError(
                    f"trex compares snippets of {length} steps, but fewer than two confidences "
                    f"are among the trajectories of at least {length} steps"
                )

    @property
    def eval_every(self) -> int:
        """Iterations per block of ``run_blocks`` (``grid.Trainer``)."""
        return self.config.trpo.eval_every

    def init(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, key: jax.Array):
        self.trpo.check_hyperparams(hyperparams.trpo)
        split_key, classifier_key, trpo_key, disc_key, eval_key, carry_key = jax.random.split(
            key, 6
        )
        split = make_split(
            split_key, self._confidence, self.num_demos, hyperparams.label_ratio,
            hyperparams.noise_std, self._allowed,
        )  # fmt: skip
        inputs = self._demo_inputs[split.indices]
        confidence, mean_labelled = self._split_confidences(spec, split, classifier_key)
        disc_params = self.discriminator.init(disc_key, inputs[0])
        trpo_state = self.trpo.init(trpo_key)
        # Keys of the appendix phases come from fold_in, so the split above (and every number
        # of the seven methods) is the same whichever phases a grid compiles.
        ranked = self._ranked_trajectories(hyperparams.label_ratio, jax.random.fold_in(key, 2))
        phase_state, trpo_state = self._init_phases(
            spec, inputs, confidence, trpo_state, jax.random.fold_in(key, 1), ranked
        )
        state = TrainState(
            trpo=trpo_state,
            discriminator_params=disc_params,
            discriminator_optimizer_state=self.optimizer.init(disc_params),
            demo_rows=split.indices,
            confidence=confidence,
            labelled=split.labelled,
            importance_weights=jnp.ones(self.num_demos),
            stats=ConfidenceStats(
                mean_confidence=confidence.mean(), mean_labelled_confidence=mean_labelled
            ),
            iteration=jnp.zeros((), jnp.int32),
            eval_keys=jax.random.split(eval_key, self.config.trpo.num_eval_episodes),
            key=carry_key,
            ranked_trajectories=ranked,
            **phase_state,
        )
        errors = confidence_errors(confidence, split.true_confidence, split.labelled)
        if not self.has_confidence:
            errors = jax.tree.map(lambda e: jnp.full_like(e, jnp.nan), errors)
        return state, {f"confidence/{name}": value for name, value in errors.items()}

    def _split_confidences(self, spec: MethodSpec, split, key: jax.Array):
        """(float[N] the confidence every split row trains with, the labelled rows' mean):
        the given one on D_c's rows; on the rest the classifier's prediction, or D_c's mean
        for a method without a classifier (``spec.classifier_coef`` 0)."""
        num_labelled = split.labelled.sum()
        mean_labelled = jnp.where(split.labelled, split.confidence, 0.0).sum() / jnp.maximum(
            num_labelled, 1
        )
        without_classifier = jnp.where(split.labelled, split.confidence, mean_labelled)

        def classify():
            predicted, _, _ = train_classifier(
                self.config.classifier,
                spec.classifier,
                self._classifier_inputs[split.indices],
                split.confidence,
                split.labelled,
                key,
            )
            return predicted

        # Under vmap a cond with a batched predicate runs both branches; alone, only one.
        predicted = jax.lax.cond(spec.classifier_coef > 0, classify, lambda: without_classifier)
        confidence = jnp.where(
            split.labelled,
            split.confidence,
            spec.classifier_coef * predicted + (1 - spec.classifier_coef) * without_classifier,
        )
        return confidence, mean_labelled

    def _ranked_trajectories(self, label_ratio, key):
        """bool[K]: a share ``label_ratio`` of the demonstration trajectories (rounded, at
        least 2), drawn per seed, whose ranking T-REX and CAIL may see: the same label
        information as the ``label_ratio`` of rows PN-GAIL's D_c holds. None when no compiled
        phase ranks demonstrations."""
        if self.trajectories is None or not {"demo_rankings", "cail"} & set(self.config.phases):
            return None
        num = self.trajectories.lengths.shape[0]
        num_ranked = jnp.maximum(jnp.round(label_ratio * num), 2)
        position = jax.random.permutation(key, num)
        return jnp.zeros(num, bool).at[position].set(jnp.arange(num) < num_ranked)

    def _init_phases(self, spec, inputs, confidence, trpo_state, key, ranked=None):
        """The appendix phases this trainer compiles: behaviour cloning of the TRPO policy,
        reward learning from rankings (T-REX's on the ``ranked`` demonstration trajectories,
        D-REX's on its own cloned policy's noisy rollouts), f-IRL's and CAIL's initial state.
        Returns (TrainState fields, trpo_state)."""
        phases, config = self.config.phases, self.config
        bc_key, noise_key, reward_key, firl_key = jax.random.split(key, 4)
        size = self.env.observation_size
        fields = {}
        normalizer = trpo_state.normalizer
        bc_params = None
        if "bc" in phases:
            weights = 1 + spec.bc_weighted_coef * (confidence - 1)
            bc_params, _ = train_bc(
                config.bc,
                lambda params, obs: self.trpo.policy.apply(params, normalizer(obs)),
                trpo_state.policy_params,
                inputs[:, :size],
                inputs[:, size:],
                weights,
                bc_key,
            )
            trpo_state = trpo_state.replace(
                policy_params=tree_where(spec.bc_init_coef > 0, bc_params, trpo_state.policy_params)
            )
        trex_key, drex_key = jax.random.split(reward_key)
        rewards = {}
        if "demo_rankings" in phases:  # T-REX: the demonstrations, ranked by confidence
            rewards["demo_rankings"], _ = ranking.train_ranking_reward(
                config.ranking, self.trajectories, trex_key, eligible=ranked
            )
        if "noise_rankings" in phases:  # D-REX: noisy rollouts of its own cloned policy
            rewards["noise_rankings"], _ = ranking.train_ranking_reward(
                config.drex.ranking, self._drex_rollouts(inputs, noise_key), drex_key
            )
        if rewards:
            fields["ranking_reward_params"] = rewards
        if "firl" in phases:
            reward_key, disc_key = jax.random.split(firl_key)
            reward = self.firl_reward.init(reward_key, jnp.zeros((size,)))
            disc = self.firl_discriminator.init(disc_key, jnp.zeros((size,)))
            fields["firl"] = FirlState(
                reward, self.firl_reward_optimizer.init(reward),
                disc, self.firl_discriminator_optimizer.init(disc),
            )  # fmt: skip
        if "cail" in phases:
            fields["cail_confidence"] = jnp.ones(self.num_demos)
        return fields, trpo_state

    def _drex_rollouts(self, inputs, key) -> ranking.Trajectories:
        """D-REX's ranked trajectories: its deterministic policy cloned from the split's
        ``inputs`` float[M, O + A] (not the TRPO policy of ``bc``), rolled out at each noise
        level of ``config.drex``."""
        size, drex = self.env.observation_size, self.config.drex
        low, high = self._action_bounds
        bc_key, rollout_key = jax.random.split(key)
        params, _ = train_deterministic_bc(
            drex.bc, inputs[:, :size], inputs[:, size:], low, high, bc_key
        )

        def act(obs):
            return cloned_actions(drex.bc, params, obs, low, high)

        return ranking.noisy_rollouts(self.env, act, drex, rollout_key)

    def _ranking_reward(self, spec: MethodSpec, params: dict, observations) -> jax.Array:
        """The learned r(s) float[B] a cell reads: D-REX's ensemble mean where
        ``spec.noise_rankings_coef`` is 1, T-REX's where it is 0 (in a grid with both, every
        cell has both and weighs them by its spec)."""
        weight = {
            "demo_rankings": 1 - spec.noise_rankings_coef,
            "noise_rankings": spec.noise_rankings_coef,
        }
        return sum(
            weight[phase] * self.ranking_rewards[phase].ensemble(phase_params, observations)
            for phase, phase_params in params.items()
        )

    def _importance_weights(self, state: TrainState) -> jax.Array:
        """WGAIL's w = [exp(-z) pi(a|s)]^(1/2) on every split row; no gradient flows."""
        inputs = self._demo_inputs[state.demo_rows]
        logits = self.discriminator.apply(state.discriminator_params, inputs)
        size = self.env.observation_size
        log_prob = self.trpo.log_prob(state.trpo, inputs[:, :size], inputs[:, size:])
        return jnp.exp(0.5 * (log_prob - logits))

    def _iteration(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, state: TrainState):
        """One iteration, as named steps: rollout; WGAIL's weights (refreshed on schedule);
        the discriminator's batch and gradient; the policy's reward from the discriminator
        (and the learned rewards) before any step; the discriminator's Adam step (CAIL's
        rounds instead, in its cells); TRPO's update (a cloned policy kept, in BC's cells)."""
        phases = self.config.phases
        trpo_state, transitions = self.trpo.rollout(state.trpo)
        weights = self._refreshed_weights(state)
        key, batch_key = jax.random.split(state.key)
        batch = self._discriminator_batch(state, transitions, batch_key)
        grads, disc_metrics, logits_agent = self._discriminator_gradient(
            spec, state, batch, weights
        )
        rewards, phase_fields, phase_metrics = self._policy_rewards(
            spec, state, transitions, batch, logits_agent, batch_key
        )
        disc_params, disc_optimizer_state = self._adam_step(
            state.discriminator_params,
            state.discriminator_optimizer_state,
            grads,
            hyperparams.discriminator_learning_rate,
        )
        if "cail" in phases:  # CAIL's cells take the discriminator of its rounds instead
            (cail_params, cail_optimizer_state, beta), cail_metrics = cail.iteration_rounds(
                self, spec, state, batch.agent_inputs, jax.random.fold_in(batch_key, 1)
            )
            use = spec.cail_coef > 0
            disc_params = tree_where(use, cail_params, disc_params)
            disc_optimizer_state = tree_where(use, cail_optimizer_state, disc_optimizer_state)
            disc_metrics["disc/loss"] = jnp.where(
                use, cail_metrics["cail/disc_loss"], disc_metrics["disc/loss"]
            )
            phase_fields["cail_confidence"] = beta
            phase_metrics = {**phase_metrics, **cail_metrics}
        updated, trpo_metrics = self.trpo.update(hyperparams.trpo, trpo_state, transitions, rewards)
        if "bc" in phases:
            updated = _keep_cloned_policy(spec, self.trpo.LEARNED_FIELDS, trpo_state, updated)
        state = state.replace(
            trpo=updated,
            discriminator_params=disc_params,
            discriminator_optimizer_state=disc_optimizer_state,
            importance_weights=weights,
            iteration=state.iteration + 1,
            key=key,
            **phase_fields,
        )
        metrics = {**trpo_metrics, **disc_metrics, **phase_metrics}
        return state, {**metrics, "env_steps": updated.env_steps}

    def _refreshed_weights(self, state: TrainState) -> jax.Array:
        """WGAIL's importance weights float[M], recomputed at iterations
        ``wgail_refresh_every``, 2 x that, ... up to ``wgail_refresh_until``, else kept."""
        config = self.config
        refresh = (
            (state.iteration > 0)
            & (state.iteration % config.wgail_refresh_every == 0)
            & (state.iteration <= config.wgail_refresh_until)
        )
        return jnp.where(refresh, self._importance_weights(state), state.importance_weights)

    def _discriminator_batch(self, state: TrainState, transitions, key) -> DiscriminatorBatch:
        """The rollout's rows (actions clipped to the bounds, as the demonstrations') and as
        many split rows drawn with replacement."""
        trpo_config = self.config.trpo
        agent_obs = transitions.obs.reshape(trpo_config.batch_size, -1)
        agent_inputs = jnp.concatenate(
            [transitions.obs, jnp.clip(transitions.action, *self._action_bounds)], axis=-1
        ).reshape(trpo_config.batch_size, -1)
        rows = jax.random.randint(key, (trpo_config.batch_size,), 0, self.num_demos)
        return DiscriminatorBatch(
            agent_obs, agent_inputs, rows, self._demo_inputs[state.demo_rows[rows]]
        )

    def _discriminator_gradient(self, spec, state: TrainState, batch, weights):
        """The gradient of the method's discriminator loss at the current parameters, its
        metrics, and the agent rows' logits (the policy's reward reads them)."""

        def loss_fn(params, confidence, stats):
            logits_agent = self.discriminator.apply(params, batch.agent_inputs)
            logits_demo = self.discriminator.apply(params, batch.demo_inputs)
            loss, metrics = discriminator_loss(
                spec,
                logits_agent,
                logits_demo,
                confidence[batch.rows],
                state.labelled[batch.rows],
                weights[batch.rows],
                stats,
            )
            if self.config.gradient_penalty:
                penalty = self._gradient_penalty(params, batch, state.key)
                metrics["disc/gradient_penalty"] = penalty
                # where, not a product: the other cells' loss keeps every bit
                loss = jnp.where(
                    spec.gradient_penalty_coef != 0,
                    loss + spec.gradient_penalty_coef * penalty,
                    loss,
                )
                metrics["disc/loss"] = loss
            return loss, (metrics, logits_agent)

        grads, (metrics, logits_agent) = jax.grad(loss_fn, has_aux=True)(
            state.discriminator_params, state.confidence, state.stats
        )
        return grads, metrics, logits_agent

    def _gradient_penalty(self, params, batch, key) -> jax.Array:
        """mean ||grad_x z(x)||^2 at x = e a + (1 - e) d between each agent row a and a
        demonstration row d of the batch, e ~ U(0, 1) per pair (a zero-centred penalty, as
        for GAN discriminators): float[]."""
        mix = jax.random.uniform(jax.random.fold_in(key, 3), (batch.agent_inputs.shape[0], 1))
        points = mix * batch.agent_inputs + (1 - mix) * batch.demo_inputs

        def logit(x):
            return self.discriminator.apply(params, x)

        gradients = jax.vmap(jax.grad(logit))(points)
        return jnp.mean(jnp.sum(gradients**2, axis=-1))

    def _policy_rewards(self, spec, state: TrainState, transitions, batch, logits_agent, key):
        """The reward float[T, N] TRPO learns from: the adversarial one from the discriminator
        before this iteration's step, plus the learned rewards of the method's phases (f-IRL's
        after its own update on this rollout, in its order). Returns the reward, the phase's
        new state fields and its metrics."""
        trpo_config, phases = self.config.trpo, self.config.phases
        rewards = policy_reward(logits_agent, spec.logit_reward_coef)
        if phases:  # every method whose reward is not (only) adversarial has a phase
            rewards = spec.adversarial_reward_coef * rewards
        phase_fields, phase_metrics = {}, {}
        if state.ranking_reward_params is not None:
            rewards += spec.ranking_reward_coef * self._ranking_reward(
                spec, state.ranking_reward_params, batch.agent_obs
            )
        if "firl" in phases:
            phase_fields["firl"], phase_metrics = firl.outer_step(
                self, spec, state, transitions.obs, jax.random.fold_in(key, 2)
            )
            rewards += spec.firl_coef * self.firl_reward.apply(
                phase_fields["firl"].reward_params, batch.agent_obs
            )
        rewards = rewards.reshape(trpo_config.unroll_length, trpo_config.num_envs)
        return rewards, phase_fields, phase_metrics

    def _adam_step(self, params, optimizer_state, grads, learning_rate):
        """One Adam step (``scale_by_adam``, then ``-learning_rate``): (params, state)."""
        updates, optimizer_state = self.optimizer.update(grads, optimizer_state)
        step = jax.tree.map(lambda u: -learning_rate * u, updates)
        return optax.apply_updates(params, step), optimizer_state

    def cail_trajectory_confidence(self, state: TrainState) -> jax.Array:
        """float[K]: CAIL's mean beta over each demonstration trajectory's rows in the split
        (NaN for a trajectory with no row in it)."""
        trajectory = self._row_trajectory[state.demo_rows]
        num = self.trajectories.lengths.shape[0]
        total = jax.ops.segment_sum(state.cail_confidence, trajectory, num)
        count = jax.ops.segment_sum(jnp.ones_like(state.cail_confidence), trajectory, num)
        return jnp.where(count > 0, total / jnp.maximum(count, 1), jnp.nan)

    def run_blocks(
        self, hyperparams: AdversarialHyperparams, spec: MethodSpec, state: TrainState, num_blocks
    ):
        return run_evaluated_blocks(
            self.trpo,
            functools.partial(self._iteration, hyperparams, spec),
            state,
            self.policy_state,
            state.eval_keys,
            num_blocks,
        )

    def train(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, key: jax.Array):
        state, init_metrics = self.init(hyperparams, spec, key)
        state, metrics = self.run_blocks(hyperparams, spec, state, self.config.trpo.num_evaluations)
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: TrainState) -> TRPOState | PPOState:
        """The learner's state inside a trainer state (for exporting its policy)."""
        return state.trpo


def _keep_cloned_policy(spec: MethodSpec, learned_fields, before, updated):
    """A cloned policy that no RL moves (BC's cells, ``policy_update_coef`` 0) stays as it
    was: the learner's ``learned_fields`` from ``before``, the rest (counters, keys, the
    envs) from ``updated``."""
    frozen = spec.policy_update_coef == 0
    return updated.replace(
        **{
            name: tree_where(frozen, getattr(before, name), getattr(updated, name))
            for name in learned_fields
        }
    )
