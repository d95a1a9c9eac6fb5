"""Adversarial imitation as one pure function: ``make_train(config, env, demos)``.

``train(hyperparams, spec, key)`` runs, for one method (``spec``, data) and one seed:

1. the split of the demonstrations into D_c (labelled) and D_u, and the confidence classifier
   where the method needs one (``spec.classifier_coef``), giving a confidence r per row;
2. ``num_iterations`` of: a TRPO rollout; the policy reward ``-log sigmoid(z)`` from the
   discriminator *before* this iteration's update; one Adam step of the discriminator on the
   agent batch and as many demonstration rows drawn with replacement; one TRPO update.

The discriminator sees agent actions clipped to the action bounds (what the environment
applies) and demonstrations in the environment's units. The reference compares unclipped agent
torques with half-scale Pendulum demonstrations; we do not copy that mismatch.

``train`` is ``init`` followed by ``run_blocks``; both are attached so a host loop can run the
same computation in chunks (``pngail_jax.grid``).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import optax
from flax import struct

from pngail_jax import envs
from pngail_jax.confidence import ClassifierConfig, confidence_errors, train_classifier
from pngail_jax.demos import DemonstrationError, Demonstrations, make_split
from pngail_jax.losses import ConfidenceStats, discriminator_loss, policy_reward
from pngail_jax.methods import MethodSpec
from pngail_jax.networks import Discriminator
from pngail_jax.rl.train import TRPO, TRPOConfig, TRPOHyperparams, TRPOState


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


def make_train(config: AdversarialConfig, env: envs.Env, demos: Demonstrations):
    """Returns ``train(hyperparams, spec, key) -> (final_state, metrics)``, pure and jittable.

    ``metrics`` maps names to float[num_iterations] (``eval/return`` is NaN except every
    ``eval_every`` iterations), plus the classifier phase's ``confidence/mae`` and
    ``confidence/rmse`` (float[], on D_u against the noise-free confidences).

    Attached: ``train.init(hyperparams, spec, key) -> (state, init_metrics)`` and
    ``train.run_blocks(hyperparams, spec, state, num_blocks) -> (state, metrics)`` (num_blocks
    static), whose composition is ``train``; ``train.trpo``; ``train.config``.
    """
    demos.check_env(env)
    if demos.confidence is None:
        raise DemonstrationError(
            "adversarial training needs a confidence per demonstration row (for GAIL or WGAIL "
            "alone, pass confidence=np.ones(n))"
        )
    num_demos = demos.num_rows if config.num_demos is None else config.num_demos
    if num_demos > demos.num_rows:
        raise DemonstrationError(
            f"num_demos={num_demos} but the demonstrations have only {demos.num_rows} rows"
        )
    trpo_config = config.trpo
    trpo = TRPO(trpo_config, env)
    discriminator = Discriminator(config.discriminator_hidden_sizes)
    optimizer = optax.scale_by_adam()
    demo_inputs = jnp.asarray(demos.inputs)
    all_confidence = jnp.asarray(demos.confidence)
    action_low, action_high = jnp.asarray(env.action_low), jnp.asarray(env.action_high)
    batch_size = trpo_config.batch_size

    def init(hyperparams: Hyperparams, spec: MethodSpec, key: jax.Array):
        split_key, classifier_key, trpo_key, disc_key, eval_key, carry_key = jax.random.split(
            key, 6
        )
        split = make_split(
            split_key, all_confidence, num_demos, hyperparams.label_ratio, hyperparams.noise_std
        )
        inputs = demo_inputs[split.indices]
        num_labelled = split.labelled.sum()
        mean_labelled = jnp.where(split.labelled, split.confidence, 0.0).sum() / jnp.maximum(
            num_labelled, 1
        )
        without_classifier = jnp.where(split.labelled, split.confidence, mean_labelled)

        def classify():
            predicted, _, _ = train_classifier(
                config.classifier,
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
        disc_params = discriminator.init(disc_key, inputs[0])
        state = TrainState(
            trpo=trpo.init(trpo_key),
            discriminator_params=disc_params,
            discriminator_optimizer_state=optimizer.init(disc_params),
            demo_rows=split.indices,
            confidence=confidence,
            labelled=split.labelled,
            importance_weights=jnp.ones(num_demos),
            stats=ConfidenceStats(
                mean_confidence=confidence.mean(), mean_labelled_confidence=mean_labelled
            ),
            iteration=jnp.zeros((), jnp.int32),
            eval_keys=jax.random.split(eval_key, trpo_config.num_eval_episodes),
            key=carry_key,
        )
        errors = confidence_errors(confidence, split.true_confidence, split.labelled)
        return state, {f"confidence/{name}": value for name, value in errors.items()}

    def importance_weights(state: TrainState) -> jax.Array:
        """WGAIL's w = [exp(-z) pi(a|s)]^(1/2) on every split row; no gradient flows."""
        inputs = demo_inputs[state.demo_rows]
        logits = discriminator.apply(state.discriminator_params, inputs)
        obs, action = inputs[:, : env.observation_size], inputs[:, env.observation_size :]
        return jnp.exp(0.5 * (trpo.log_prob(state.trpo, obs, action) - logits))

    def iteration(hyperparams: Hyperparams, spec: MethodSpec, state: TrainState):
        trpo_state, transitions = trpo.rollout(state.trpo)
        refresh = (
            (state.iteration > 0)
            & (state.iteration % config.wgail_refresh_every == 0)
            & (state.iteration <= config.wgail_refresh_until)
        )
        weights = jnp.where(refresh, importance_weights(state), state.importance_weights)
        agent_inputs = jnp.concatenate(
            [transitions.obs, jnp.clip(transitions.action, action_low, action_high)], axis=-1
        ).reshape(batch_size, -1)
        key, batch_key = jax.random.split(state.key)
        rows = jax.random.randint(batch_key, (batch_size,), 0, num_demos)
        demo_batch = demo_inputs[state.demo_rows[rows]]

        def loss_fn(params):
            logits_agent = discriminator.apply(params, agent_inputs)
            logits_demo = discriminator.apply(params, demo_batch)
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
        updates, disc_optimizer_state = optimizer.update(grads, state.discriminator_optimizer_state)
        disc_params = optax.apply_updates(
            state.discriminator_params,
            jax.tree.map(lambda u: -hyperparams.discriminator_learning_rate * u, updates),
        )
        trpo_state, trpo_metrics = trpo.update(hyperparams.trpo, trpo_state, transitions, rewards)
        state = state.replace(
            trpo=trpo_state,
            discriminator_params=disc_params,
            discriminator_optimizer_state=disc_optimizer_state,
            importance_weights=weights,
            iteration=state.iteration + 1,
            key=key,
        )
        return state, {**trpo_metrics, **disc_metrics, "env_steps": trpo_state.env_steps}

    def block(hyperparams: Hyperparams, spec: MethodSpec, state: TrainState):
        state, metrics = jax.lax.scan(
            lambda s, _: iteration(hyperparams, spec, s), state, None, length=trpo_config.eval_every
        )
        eval_return = trpo.evaluate(state.trpo, state.eval_keys)
        metrics["eval/return"] = (
            jnp.full((trpo_config.eval_every,), jnp.nan).at[-1].set(eval_return)
        )
        return state, metrics

    def run_blocks(hyperparams: Hyperparams, spec: MethodSpec, state: TrainState, num_blocks):
        """``num_blocks`` (static) blocks of ``eval_every`` iterations; metrics float[I]."""
        state, metrics = jax.lax.scan(
            lambda s, _: block(hyperparams, spec, s), state, None, length=num_blocks
        )
        return state, jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), metrics)

    def train(hyperparams: Hyperparams, spec: MethodSpec, key: jax.Array):
        state, init_metrics = init(hyperparams, spec, key)
        state, metrics = run_blocks(hyperparams, spec, state, trpo_config.num_evaluations)
        return state, {**metrics, **init_metrics}

    train.init = init
    train.run_blocks = run_blocks
    train.trpo = trpo
    train.config = config
    train.num_demos = num_demos
    return train
