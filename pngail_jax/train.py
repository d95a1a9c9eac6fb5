"""Adversarial imitation as one pure program: ``AdversarialTrainer(config, env, demos)``.

``trainer.train(hyperparams, spec, key)`` runs, for one method (``spec``, data) and one seed:

1. the split of the demonstrations into D_c (labelled) and D_u, and the confidence classifier
   where the method needs one (``spec.classifier_coef``), giving a confidence r per row;
2. ``num_iterations`` of: a TRPO rollout; the policy reward ``-log sigmoid(z)`` from the
   discriminator *before* this iteration's update; one Adam step of the discriminator on the
   agent batch and as many demonstration rows drawn with replacement; one TRPO update.

The discriminator sees agent actions clipped to the action bounds (what the environment
applies) and demonstrations in the environment's units. The reference compares unclipped agent
torques with half-scale Pendulum demonstrations; we do not copy that mismatch.

``train`` is ``init`` followed by ``run_blocks``, so a host loop can run the same computation
in chunks (``pngail_jax.grid``).
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from pngail_jax import envs
from pngail_jax.confidence import ClassifierConfig, confidence_errors, train_classifier
from pngail_jax.demos import DemonstrationError, Demonstrations, make_split
from pngail_jax.losses import ConfidenceStats, discriminator_loss, policy_reward
from pngail_jax.methods import PRESETS, MethodSpec
from pngail_jax.networks import Discriminator
from pngail_jax.rl.train import (
    TRPO,
    TRPOConfig,
    TRPOHyperparams,
    TRPOState,
    run_evaluated_blocks,
)


@dataclasses.dataclass(frozen=True)
class AdversarialConfig:
    """Static settings (shapes, counts, schedules) of an adversarial run."""

    trpo: TRPOConfig = TRPOConfig()
    classifier: ClassifierConfig = ClassifierConfig()
    # Rows per split (the paper's n_c + n_u); None = every demonstration row.
    num_demos: int | None = None
    discriminator_hidden_sizes: tuple[int, ...] = (100, 100)
    # WGAIL refreshes its weights at iterations every, 2 every, ..., until (w = 1 before).
    wgail_refresh_every: int = 50
    wgail_refresh_until: int = 400

    def __post_init__(self):
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
class Hyperparams:
    """Per-cell values a grid may vary (pytree leaves)."""

    trpo: TRPOHyperparams
    discriminator_learning_rate: jax.Array
    label_ratio: jax.Array  # fraction of the split that is labelled (D_c)
    noise_std: jax.Array  # confidence noise: r <- clip(r + N(0, noise_std^2), 0, 1)

    @classmethod
    def create(
        cls,
        label_ratio=0.2,
        noise_std=0.0,
        discriminator_learning_rate=1e-3,
        **trpo_hyperparams,
    ) -> Hyperparams:
        if not 0 < label_ratio < 1:
            raise ValueError(f"label_ratio must be in (0, 1), got {label_ratio!r}")
        if not noise_std >= 0:
            raise ValueError(f"noise_std must be >= 0, got {noise_std!r}")
        if not discriminator_learning_rate > 0:
            raise ValueError(
                f"discriminator_learning_rate must be positive, got {discriminator_learning_rate!r}"
            )
        return cls(
            trpo=TRPOHyperparams.create(**trpo_hyperparams),
            discriminator_learning_rate=jnp.asarray(discriminator_learning_rate, jnp.float32),
            label_ratio=jnp.asarray(label_ratio, jnp.float32),
            noise_std=jnp.asarray(noise_std, jnp.float32),
        )


@struct.dataclass
class TrainState:
    trpo: TRPOState
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
        self.trpo = TRPO(config.trpo, env)
        self.discriminator = Discriminator(config.discriminator_hidden_sizes)
        self.optimizer = optax.scale_by_adam()
        self._demo_inputs = jnp.asarray(demos.inputs)
        # Without confidences every row gets r = 1; no method that reads r may run then.
        self._confidence = jnp.asarray(
            demos.confidence if self.has_confidence else np.ones(demos.num_rows, np.float32)
        )
        self._action_bounds = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
        # The rows whose confidence a learner may see (the file's ``labelled`` mask; None: all).
        has_mask = self.has_confidence and demos.labelled is not None
        self._allowed = jnp.asarray(demos.labelled) if has_mask else None
        self.num_allowed = int(demos.labelled.sum()) if has_mask else demos.num_rows

    def check_label_ratios(self, label_ratios) -> None:
        """Raises ``DemonstrationError`` when the demonstrations' ``labelled`` mask allows
        fewer rows than the largest ratio labels, ``round(label_ratio * num_demos)``; call it on
        the host before building a grid (the split itself labels at most the allowed rows)."""
        largest = max(float(ratio) for ratio in label_ratios)
        requested = round(largest * self.num_demos)
        if self.has_confidence and requested > self.num_allowed:
            raise DemonstrationError(
                f"label ratio {largest:g} of {self.num_demos} rows asks for {requested} labelled "
                f"rows, but the demonstrations' labelled mask allows only {self.num_allowed}"
            )

    def check_methods(self, methods) -> None:
        """Raises ``DemonstrationError`` naming the methods that need confidences the
        demonstrations do not carry."""
        readers = [name for name in methods if PRESETS[name].confidence_source != "none"]
        if not self.has_confidence and readers:
            raise DemonstrationError(
                f"the demonstrations carry no confidences, which {', '.join(readers)} read; "
                "give a confidence file, or run only methods that read none (gail, wgail)"
            )

    def init(self, hyperparams: Hyperparams, spec: MethodSpec, key: jax.Array):
        split_key, classifier_key, trpo_key, disc_key, eval_key, carry_key = jax.random.split(
            key, 6
        )
        split = make_split(
            split_key, self._confidence, self.num_demos, hyperparams.label_ratio,
            hyperparams.noise_std, self._allowed,
        )  # fmt: skip
        inputs = self._demo_inputs[split.indices]
        num_labelled = split.labelled.sum()
        mean_labelled = jnp.where(split.labelled, split.confidence, 0.0).sum() / jnp.maximum(
            num_labelled, 1
        )
        without_classifier = jnp.where(split.labelled, split.confidence, mean_labelled)

        def classify():
            predicted, _, _ = train_classifier(
                self.config.classifier,
                spec.classifier,
                inputs,
                split.confidence,
                split.labelled,
                classifier_key,
            )
            return predicted

        # Under vmap a cond with a batched predicate runs both branches; alone, only one.
        predicted = jax.lax.cond(spec.classifier_coef > 0, classify, lambda: without_classifier)
        confidence = jnp.where(
            split.labelled,
            split.confidence,
            spec.classifier_coef * predicted + (1 - spec.classifier_coef) * without_classifier,
        )
        disc_params = self.discriminator.init(disc_key, inputs[0])
        state = TrainState(
            trpo=self.trpo.init(trpo_key),
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
        )
        errors = confidence_errors(confidence, split.true_confidence, split.labelled)
        if not self.has_confidence:
            errors = jax.tree.map(lambda e: jnp.full_like(e, jnp.nan), errors)
        return state, {f"confidence/{name}": value for name, value in errors.items()}

    def _importance_weights(self, state: TrainState) -> jax.Array:
        """WGAIL's w = [exp(-z) pi(a|s)]^(1/2) on every split row; no gradient flows."""
        inputs = self._demo_inputs[state.demo_rows]
        logits = self.discriminator.apply(state.discriminator_params, inputs)
        size = self.env.observation_size
        log_prob = self.trpo.log_prob(state.trpo, inputs[:, :size], inputs[:, size:])
        return jnp.exp(0.5 * (log_prob - logits))

    def _iteration(self, hyperparams: Hyperparams, spec: MethodSpec, state: TrainState):
        config, trpo_config = self.config, self.config.trpo
        trpo_state, transitions = self.trpo.rollout(state.trpo)
        refresh = (
            (state.iteration > 0)
            & (state.iteration % config.wgail_refresh_every == 0)
            & (state.iteration <= config.wgail_refresh_until)
        )
        weights = jnp.where(refresh, self._importance_weights(state), state.importance_weights)
        agent_inputs = jnp.concatenate(
            [transitions.obs, jnp.clip(transitions.action, *self._action_bounds)], axis=-1
        ).reshape(trpo_config.batch_size, -1)
        key, batch_key = jax.random.split(state.key)
        rows = jax.random.randint(batch_key, (trpo_config.batch_size,), 0, self.num_demos)
        demo_batch = self._demo_inputs[state.demo_rows[rows]]

        def loss_fn(params):
            logits_agent = self.discriminator.apply(params, agent_inputs)
            logits_demo = self.discriminator.apply(params, demo_batch)
            loss, metrics = discriminator_loss(
                spec,
                logits_agent,
                logits_demo,
                state.confidence[rows],
                state.labelled[rows],
                weights[rows],
                state.stats,
            )
            return loss, (metrics, logits_agent)

        grads, (disc_metrics, logits_agent) = jax.grad(loss_fn, has_aux=True)(
            state.discriminator_params
        )
        # The reward comes from the discriminator before this iteration's step.
        rewards = policy_reward(logits_agent).reshape(
            trpo_config.unroll_length, trpo_config.num_envs
        )
        updates, disc_optimizer_state = self.optimizer.update(
            grads, state.discriminator_optimizer_state
        )
        disc_params = optax.apply_updates(
            state.discriminator_params,
            jax.tree.map(lambda u: -hyperparams.discriminator_learning_rate * u, updates),
        )
        trpo_state, trpo_metrics = self.trpo.update(
            hyperparams.trpo, trpo_state, transitions, rewards
        )
        state = state.replace(
            trpo=trpo_state,
            discriminator_params=disc_params,
            discriminator_optimizer_state=disc_optimizer_state,
            importance_weights=weights,
            iteration=state.iteration + 1,
            key=key,
        )
        return state, {**trpo_metrics, **disc_metrics, "env_steps": trpo_state.env_steps}

    def run_blocks(self, hyperparams: Hyperparams, spec: MethodSpec, state: TrainState, num_blocks):
        return run_evaluated_blocks(
            self.trpo,
            functools.partial(self._iteration, hyperparams, spec),
            state,
            self.policy_state,
            state.eval_keys,
            num_blocks,
        )

    def train(self, hyperparams: Hyperparams, spec: MethodSpec, key: jax.Array):
        state, init_metrics = self.init(hyperparams, spec, key)
        state, metrics = self.run_blocks(hyperparams, spec, state, self.config.trpo.num_evaluations)
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: TrainState) -> TRPOState:
        """The learner's state inside a trainer state (for exporting its policy)."""
        return state.trpo
