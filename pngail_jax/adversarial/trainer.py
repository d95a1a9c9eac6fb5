"""Adversarial imitation as one pure program: ``AdversarialTrainer(config, env, demos)``.

``trainer.train(hyperparams, spec, key)`` runs, for one method (``spec``, data) and one seed:

1. the split of the demonstrations into D_c (labelled) and D_u, and the confidence classifier
   where the method needs one (``spec.classifier_coef``), giving a confidence r per row;
2. ``num_iterations`` of: a rollout; the policy reward ``-log sigmoid(z)`` from the
   discriminator *before* this iteration's update; one Adam step of the discriminator on the
   agent batch and as many demonstration rows drawn with replacement; one update of the
   policy learner (TRPO, the paper's, or PPO: ``AdversarialConfig.learner.name``).

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

from pngail_jax import envs
from pngail_jax.adversarial import cail, firl, ranking
from pngail_jax.adversarial.bc import BCConfig, CloningPhase
from pngail_jax.adversarial.firl import FirlState
from pngail_jax.adversarial.losses import ConfidenceStats, discriminator_loss, policy_reward
from pngail_jax.adversarial.method_checks import check_label_ratios, check_methods
from pngail_jax.adversarial.methods import PHASES, MethodSpec
from pngail_jax.adversarial.phase import PhaseContext, PhaseSet
from pngail_jax.confidence import ClassifierConfig, confidence_errors, split_confidences
from pngail_jax.config.learner import (
    LearnerConfig,
    MovedSetting,
    check_discriminator_learning_rate,
    learner_with_settings,
)
from pngail_jax.demos import DemonstrationError, Demonstrations, make_split
from pngail_jax.fitting import adam_step
from pngail_jax.networks import Discriminator
from pngail_jax.rl.learners import learner_hyperparams, make_learner
from pngail_jax.rl.on_policy import RolloutConfig, run_evaluated_blocks
from pngail_jax.rl.ppo import PPOConfig, PPOHyperparams, PPOState
from pngail_jax.rl.trpo import TRPOConfig, TRPOHyperparams, TRPOState


@dataclasses.dataclass(frozen=True)
class AdversarialConfig:
    """Static settings (shapes, counts, schedules) of an adversarial run."""

    # The rollout's shape, the run's length and the policy and value networks (both learners).
    rollout: RolloutConfig = RolloutConfig()
    # The policy learner's part, as every job config's (``config.learner.LearnerConfig``): its
    # name, "trpo" (the paper's) or "ppo" (``rl.learners``), and each one's own settings (the
    # one that does not run is not read). A name alone is that learner at its defaults.
    learner: LearnerConfig = LearnerConfig()
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
    # Compile the confidence classifier (MethodSpec.classifier_coef 1: 2IWIL, PN-GAIL and its
    # ablations, weighted BC). Under vmap init runs it for every cell, read or not, so a grid
    # in which no cell reads it (GAIL, IC-GAIL, WGAIL, most appendix baselines) leaves it out:
    # 45% of init's compile on Pendulum, the same numbers (``methods.trains_classifier``).
    confidence_classifier: bool = True
    # Deprecated (gone in 0.3): the learner's settings beside it, as before the learner part;
    # given, each replaces ``learner``'s own with a DeprecationWarning. Init-only, so neither
    # is a field (``dataclasses.asdict``, config.json and equality see ``learner`` alone).
    # Not given, each reads as a ``MovedSetting``: reading ``config.trpo`` as before raises
    # one line naming ``config.learner.trpo`` instead of reading None (the defaults).
    trpo: dataclasses.InitVar[TRPOConfig | None] = MovedSetting(
        "AdversarialConfig.trpo", "AdversarialConfig.learner.trpo"
    )
    ppo: dataclasses.InitVar[PPOConfig | None] = MovedSetting(
        "AdversarialConfig.ppo", "AdversarialConfig.learner.ppo"
    )

    def __post_init__(self, trpo, ppo):
        part = learner_with_settings(self.learner, "AdversarialConfig", trpo, ppo, stacklevel=4)
        object.__setattr__(self, "learner", part)  # frozen: set once, here
        part.check_batch(self.rollout)
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
    """Per-cell values a grid may vary (pytree leaves). ``learner`` holds the policy learner's
    hyperparameters, TRPO's or PPO's."""

    learner: TRPOHyperparams | PPOHyperparams
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
        check_discriminator_learning_rate(discriminator_learning_rate)
        return cls(
            learner=learner_hyperparams(learner, **learner_values),
            discriminator_learning_rate=jnp.asarray(discriminator_learning_rate, jnp.float32),
            label_ratio=jnp.asarray(label_ratio, jnp.float32),
            noise_std=jnp.asarray(noise_std, jnp.float32),
        )


@struct.dataclass
class TrainState:
    learner: TRPOState | PPOState  # the policy learner's state
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

    The trainer interface shared with ``pngail_jax.rl.PolicyTrainer`` (and used by
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
        # The policy learner, TRPO or PPO (``rl.learners``).
        self.learner = make_learner(config.learner, config.rollout, env)
        self.discriminator = Discriminator(config.discriminator_hidden_sizes)
        self.optimizer = optax.scale_by_adam()
        # One action space on both sides of every learned comparison with the agent (the
        # discriminator, WGAIL's weights, BC, CAIL's rankings): the action the environment
        # applies. The agent's actions are clipped to the bounds in ``iteration``, the
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
        self.trajectories = row_trajectory = None
        if demos.trajectory_ids is not None and self.has_confidence:
            self.trajectories, row_trajectory = ranking.trajectories_of(
                applied.observations, applied.actions, demos.trajectory_ids, demos.confidence
            )
        context = PhaseContext(
            env, self.learner, self.discriminator, self._demo_inputs, self._action_bounds,
            num_demos, config.rollout.num_envs, config.rollout.unroll_length,
            self.trajectories, row_trajectory,
        )  # fmt: skip
        self.phases = PhaseSet(context, _make_phases(config, demos.trajectory_ids))

    @property
    def demo_inputs(self) -> jax.Array:
        """float[N, O + A]: every demonstration row as the discriminator sees it (actions
        clipped to the action bounds)."""
        return self._demo_inputs

    def check_label_ratios(self, label_ratios) -> None:
        """``method_checks.check_label_ratios`` for this trainer's demonstrations; call it on
        the host before building a grid (the split itself labels at most the allowed rows)."""
        check_label_ratios(
            label_ratios, self.num_demos, self.config.classifier,
            self.num_allowed if self.has_confidence else None,
        )  # fmt: skip

    def check_methods(self, methods) -> None:
        """``method_checks.check_methods`` against what this trainer has and compiles."""
        check_methods(
            methods, self.has_confidence, self.config.phases, self.config.gradient_penalty,
            self.trajectories, self.config.ranking, self.config.confidence_classifier,
        )  # fmt: skip

    @property
    def eval_every(self) -> int:
        """Iterations per block of ``run_blocks`` (``grid.Trainer``)."""
        return self.config.rollout.eval_every

    def init(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, key: jax.Array):
        self.learner.check_hyperparams(hyperparams.learner)
        split_key, classifier_key, learner_key, disc_key, eval_key, carry_key = jax.random.split(
            key, 6
        )
        split = make_split(
            split_key, self._confidence, self.num_demos, hyperparams.label_ratio,
            hyperparams.noise_std, self._allowed,
        )  # fmt: skip
        inputs = self._demo_inputs[split.indices]
        confidence, mean_labelled = split_confidences(
            self.config.classifier, spec.classifier, spec.classifier_coef,
            self._classifier_inputs[split.indices], split, classifier_key,
            compiled=self.config.confidence_classifier,
        )  # fmt: skip
        disc_params = self.discriminator.init(disc_key, inputs[0])
        learner_state = self.learner.init(learner_key)
        # The appendix phases' keys come from fold_in, so the split above (and every number
        # of the seven methods) is the same whichever phases a grid compiles.
        phase_state, learner_state = self.phases.init(
            spec, inputs, confidence, learner_state, key, hyperparams.label_ratio
        )
        state = TrainState(
            learner=learner_state,
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
            eval_keys=jax.random.split(eval_key, self.config.rollout.num_eval_episodes),
            key=carry_key,
            **phase_state,
        )
        errors = confidence_errors(confidence, split.true_confidence, split.labelled)
        if not self.has_confidence:
            errors = jax.tree.map(lambda e: jnp.full_like(e, jnp.nan), errors)
        return state, {f"confidence/{name}": value for name, value in errors.items()}

    def importance_weights(self, state: TrainState) -> jax.Array:
        """WGAIL's w = [exp(-z) pi(a|s)]^(1/2) on every split row; no gradient flows."""
        inputs = self._demo_inputs[state.demo_rows]
        logits = self.discriminator.apply(state.discriminator_params, inputs)
        size = self.env.observation_size
        log_prob = self.learner.log_prob(state.learner, inputs[:, :size], inputs[:, size:])
        return jnp.exp(0.5 * (log_prob - logits))

    def iteration(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, state: TrainState):
        """One iteration, as named steps: rollout; WGAIL's weights (refreshed on schedule);
        the discriminator's batch and gradient; the policy's reward from the discriminator
        (and the phases' learned rewards) before any step; the discriminator's Adam step (CAIL's
        rounds instead, in its cells); the learner's update (a cloned policy kept, in BC's
        cells)."""
        learner_state, transitions = self.learner.rollout(state.learner)
        weights = self._refreshed_weights(state)
        key, batch_key = jax.random.split(state.key)
        batch = self.discriminator_batch(state, transitions, batch_key)
        grads, disc_metrics, logits_agent = self.discriminator_gradient(spec, state, batch, weights)
        rewards, phase_fields, phase_metrics = self.policy_rewards(
            spec, state, transitions, batch, logits_agent, batch_key
        )
        stepped = adam_step(
            state.discriminator_params,
            state.discriminator_optimizer_state,
            grads,
            hyperparams.discriminator_learning_rate,
        )
        (disc_params, disc_optimizer_state, disc_metrics), more_fields, more_metrics = (
            self.phases.discriminator_step(spec, state, batch, batch_key, (*stepped, disc_metrics))
        )
        updated, learner_metrics = self.learner.update(
            hyperparams.learner, learner_state, transitions, rewards
        )
        updated = self.phases.after_update(spec, learner_state, updated)
        state = state.replace(
            learner=updated,
            discriminator_params=disc_params,
            discriminator_optimizer_state=disc_optimizer_state,
            importance_weights=weights,
            iteration=state.iteration + 1,
            key=key,
            **phase_fields,
            **more_fields,
        )
        metrics = {**learner_metrics, **disc_metrics, **phase_metrics, **more_metrics}
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
        return jnp.where(refresh, self.importance_weights(state), state.importance_weights)

    def discriminator_batch(self, state: TrainState, transitions, key) -> DiscriminatorBatch:
        """The rollout's rows (actions clipped to the bounds, as the demonstrations') and as
        many split rows drawn with replacement."""
        rollout = self.config.rollout
        agent_obs = transitions.obs.reshape(rollout.batch_size, -1)
        agent_inputs = jnp.concatenate(
            [transitions.obs, jnp.clip(transitions.action, *self._action_bounds)], axis=-1
        ).reshape(rollout.batch_size, -1)
        rows = jax.random.randint(key, (rollout.batch_size,), 0, self.num_demos)
        return DiscriminatorBatch(
            agent_obs, agent_inputs, rows, self._demo_inputs[state.demo_rows[rows]]
        )

    def discriminator_gradient(self, spec, state: TrainState, batch, weights):
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

    def policy_rewards(self, spec, state: TrainState, transitions, batch, logits_agent, key):
        """The reward float[T, N] the learner learns from: the adversarial one from the
        discriminator before this iteration's step, plus the compiled phases' learned rewards
        (f-IRL's after its own update on this rollout). Returns the reward, the phases' new
        state fields and their metrics."""
        rewards = policy_reward(logits_agent, spec.logit_reward_coef)
        if self.phases:  # every method whose reward is not (only) adversarial has a phase
            rewards = spec.adversarial_reward_coef * rewards
        rewards, fields, metrics = self.phases.reward(spec, state, transitions, batch, rewards, key)
        shape = (self.config.rollout.unroll_length, self.config.rollout.num_envs)
        return rewards.reshape(shape), fields, metrics

    def run_blocks(
        self, hyperparams: AdversarialHyperparams, spec: MethodSpec, state: TrainState, num_blocks
    ):
        return run_evaluated_blocks(
            self.learner,
            functools.partial(self.iteration, hyperparams, spec),
            state,
            self.policy_state,
            state.eval_keys,
            num_blocks,
        )

    def train(self, hyperparams: AdversarialHyperparams, spec: MethodSpec, key: jax.Array):
        state, init_metrics = self.init(hyperparams, spec, key)
        state, metrics = self.run_blocks(
            hyperparams, spec, state, self.config.rollout.num_evaluations
        )
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: TrainState) -> TRPOState | PPOState:
        """The learner's state inside a trainer state (for exporting its policy)."""
        return state.learner


def _make_phases(config: AdversarialConfig, trajectory_ids) -> tuple:
    """The appendix baselines' phases ``config.phases`` names, in their order."""
    names, phases = config.phases, []
    if "bc" in names:
        phases.append(CloningPhase(config.bc))
    rankings = tuple(name for name in ("demo_rankings", "noise_rankings") if name in names)
    if rankings:
        phases.append(ranking.RankingPhase(rankings, config.ranking, config.drex))
    if "firl" in names:
        phases.append(firl.FirlPhase(config.firl, trajectory_ids))
    if "cail" in names:
        phases.append(cail.CailPhase(config.cail))
    return tuple(phases)
