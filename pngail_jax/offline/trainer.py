"""Offline imitation from imperfect demonstrations as one pure program: ``OfflineTrainer``.

The offline family never touches the environment while it learns (only to evaluate): it
weights or selects the demonstrations for behaviour cloning. Like the adversarial methods, a
method is data, an ``OfflineSpec`` of coefficients over a few shared terms, so BC on the
expert rows, BC on every row, DWBC and ISW-BC train in one ``jit(vmap)`` grid:

    L_pi = expert_bc_coef mean_E[nll] + union_bc_coef mean_U[nll]
         + dwbc_coef (alpha mean_E[nll] - mean_E[w_E nll] + mean_O[w_O nll])
         + iswbc_coef mean_U[w(x) nll]
         + ilid_coef (mean_{E+S}[d / (1 - d) nll] + mean_S[nll])
         + policy_weight_decay / 2 ||theta||^2

with E a batch of the expert rows, O of the other rows, U of every row, S of the rows ILID
selects (other rows whose next K states reach an expert-like state; ILID's two
discriminators train before the policy, in ``init``, by ``offline_ilid``; ``ilid_union``
"released" pads E+S with zero rows as its released code samples it) (docs/methods.md,
"Offline methods"; the losses in ``offline_losses``). The data they see is what PN-GAIL sees:
each seed's split of the demonstrations into a labelled share D_c (``label_ratio``) and the
unlabelled rest D_u. The expert set is D_c's rows at confidence >= ``expert_threshold``, plus,
where ``classifier_coef`` is 1, D_u's rows whose BSC-predicted confidence reaches it.

The trainer interface is ``Grid``'s (``init`` / ``run_blocks`` / ``policy_state``): an
iteration is ``steps_per_iteration`` gradient steps, a block ``eval_every`` iterations ending
in the online grid's evaluation (the deterministic policy on fixed-key episodes).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from pngail_jax import envs
from pngail_jax.confidence import (
    ClassifierConfig,
    ClassifierSpec,
    confidence_errors,
    train_classifier,
)
from pngail_jax.demos import Demonstrations, make_split, successor_rows
from pngail_jax.fitting import adam_step, squared_norm, tree_where
from pngail_jax.networks import (
    GaussianPolicy,
    LogDensityDiscriminator,
    LogitDiscriminator,
    gaussian_log_density,
)
from pngail_jax.offline.ilid import IlidSelection, check_union, uniform_over, with_zero_rows
from pngail_jax.offline.losses import (
    dwbc_discriminator_loss,
    dwbc_evaluation_metrics,
    dwbc_policy_loss,
    iswbc_discriminator_loss,
    iswbc_log_odds,
    iswbc_weights,
    log_density_feature,
    one_centred_penalty,
    weighted_nll,
)
from pngail_jax.rl.on_policy import ObservationNormalizer
from pngail_jax.rl.rollout import evaluate

# The parts a grid compiles only when one of its methods needs them.
COMPONENTS = ("dwbc", "iswbc", "ilid", "classifier")
# metrics.csv's columns beyond the sweep's (report.CSV_COLUMNS), where a cell records them:
# DWBC's discriminator on the whole split at each evaluation (empty between evaluations).
METRICS_CSV_COLUMNS = {
    "dwbc_d_expert": "dwbc/eval_d_expert",
    "dwbc_d_other": "dwbc/eval_d_other",
    "dwbc_weight_expert": "dwbc/eval_weight_expert",
    "dwbc_weight_other": "dwbc/eval_weight_other",
}


@dataclasses.dataclass(frozen=True)
class OfflineConfig:
    """Static settings: counts and shapes every cell of a grid shares."""

    num_iterations: int = 100
    steps_per_iteration: int = 1_000  # gradient steps per iteration
    eval_every: int = 5  # iterations per evaluation (5,000 steps: DWBC's codebase)
    num_eval_episodes: int = 32
    batch_size: int = 256  # rows per batch, each of E, O and U (both codebases: 256)
    hidden_sizes: tuple[int, ...] = (100, 100)  # the online grid's Gaussian policy
    num_demos: int | None = None  # rows per split; None = every row
    dwbc_discriminator_every: int = 100  # DWBC steps its discriminator every 100th step
    dwbc_branch_size: int = 128
    dwbc_hidden_size: int = 256
    iswbc_hidden_sizes: tuple[int, ...] = (256, 256)
    ilid_hidden_sizes: tuple[int, ...] = (256, 256)  # both ILID discriminators (its codebase)
    ilid_rollback: int = 20  # K: a row is selected if one of its next K states is expert-like
    ilid_discriminator_steps: int = 100_000  # each ILID discriminator, before the policy
    ilid_union: str = "intended"  # E+S, or "released": padded with zero rows (offline_ilid)
    classifier: ClassifierConfig = ClassifierConfig()
    components: tuple[str, ...] = ()  # of COMPONENTS; ``required_components(methods)``

    def __post_init__(self):
        for name in (
            "num_iterations", "steps_per_iteration", "eval_every", "num_eval_episodes",
            "batch_size", "dwbc_discriminator_every", "dwbc_branch_size", "dwbc_hidden_size",
            "ilid_rollback", "ilid_discriminator_steps",
        ):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"OfflineConfig.{name} must be a positive integer, got {value!r}")
        if self.num_iterations % self.eval_every:
            raise ValueError(
                f"OfflineConfig.num_iterations ({self.num_iterations}) must be a multiple of "
                f"eval_every ({self.eval_every})"
            )
        unknown = [c for c in self.components if c not in COMPONENTS]
        if unknown or len(set(self.components)) != len(self.components):
            raise ValueError(
                f"OfflineConfig.components must be distinct names from {COMPONENTS}, "
                f"got {self.components!r}"
            )
        if self.num_demos is not None and (
            isinstance(self.num_demos, bool) or not isinstance(self.num_demos, int)
            or self.num_demos < 2
        ):  # fmt: skip
            raise ValueError(f"OfflineConfig.num_demos must be an integer >= 2 or None, "
                             f"got {self.num_demos!r}")  # fmt: skip
        check_union(self.ilid_union, "OfflineConfig.ilid_union")

    @property
    def num_evaluations(self) -> int:
        return self.num_iterations // self.eval_every

    @property
    def num_gradient_steps(self) -> int:
        return self.num_iterations * self.steps_per_iteration


@struct.dataclass
class OfflineSpec:
    """One offline method as data (float[] leaves)."""

    expert_bc_coef: jax.Array  # + coef mean_E[nll]
    union_bc_coef: jax.Array  # + coef mean_U[nll]
    dwbc_coef: jax.Array  # DWBC's discriminator and its weighted BC
    iswbc_coef: jax.Array  # ISW-BC's discriminator and its importance-weighted BC
    classifier_coef: jax.Array  # 1: D_u rows with BSC confidence >= threshold are expert too
    bsc_eps: jax.Array  # BSC's clip (the task's: 0.05 on Walker2d, as the online grid's)
    expert_threshold: jax.Array  # expert rows: confidence >= this
    policy_learning_rate: jax.Array
    discriminator_learning_rate: jax.Array
    policy_weight_decay: jax.Array  # coupled L2 (torch's Adam weight_decay)
    dwbc_alpha: jax.Array
    dwbc_eta: jax.Array
    iswbc_penalty_coef: jax.Array  # the one-centred gradient penalty's weight
    iswbc_cutoff: jax.Array  # weights below it count 0 (the codebase: 0, none cut)
    ilid_coef: jax.Array  # ILID's selected rows and its importance-weighted BC
    ilid_bar: jax.Array  # a state is expert-like when the state discriminator's d >= this
    ilid_discriminator_learning_rate: jax.Array
    ilid_discriminator_weight_decay: jax.Array  # coupled L2, as torch's Adam weight_decay
    num_gradient_steps: jax.Array  # the policy stops learning after these many steps

    @property
    def classifier(self) -> ClassifierSpec:
        return ClassifierSpec(bsc_coef=jnp.ones_like(self.classifier_coef), eps=self.bsc_eps)


@struct.dataclass
class OfflineHyperparams:
    """A cell's setting: the split's label ratio and its confidence noise."""

    label_ratio: jax.Array
    noise_std: jax.Array

    @classmethod
    def create(cls, label_ratio=0.2, noise_std=0.0) -> OfflineHyperparams:
        if not 0 < label_ratio < 1:
            raise ValueError(f"label_ratio must be in (0, 1), got {label_ratio!r}")
        if not noise_std >= 0:
            raise ValueError(f"noise_std must be >= 0, got {noise_std!r}")
        return cls(jnp.float32(label_ratio), jnp.float32(noise_std))


@struct.dataclass
class OfflineState:
    policy_params: dict
    policy_optimizer_state: optax.OptState
    normalizer: ObservationNormalizer  # the split's observation mean and std, fixed
    demo_rows: jax.Array  # int32[M]: the split's rows of the demonstration set
    expert_probability: jax.Array  # float32[M]: uniform over the expert rows
    other_probability: jax.Array  # float32[M]: uniform over the other rows
    step: jax.Array  # int32[]: gradient steps taken
    eval_keys: jax.Array
    key: jax.Array
    dwbc_params: dict | None = None
    dwbc_optimizer_state: optax.OptState | None = None
    iswbc_params: dict | None = None
    iswbc_optimizer_state: optax.OptState | None = None
    ilid_selected_probability: jax.Array | None = None  # float32[M]: uniform over S
    ilid_union_probability: jax.Array | None = None  # float32[M]: uniform over E and S
    ilid_weight: jax.Array | None = None  # float32[M]: d / (1 - d) of the (s, a) discriminator
    # ilid_union "released" only: the share of union draws that are zero rows, float32[], and
    # a zero row's weight d / (1 - d), float32[] (None otherwise: older checkpoints restore).
    ilid_zero_share: jax.Array | None = None
    ilid_zero_weight: jax.Array | None = None


class OfflineTrainer:
    """Offline imitation of ``demos``, evaluated in ``env``, one method (an ``OfflineSpec``)
    per call; the cell inputs are ``(hyperparams, spec)``:

    - ``init(hyperparams, spec, key) -> (state, init_metrics)``: the split, the expert set
      (and the classifier, where it is compiled), the networks; ``init_metrics``:
      ``offline/num_expert``, ``offline/expert_true_confidence`` (the expert rows' mean given
      confidence before noise: how clean the expert set is), ``confidence/mae`` and ``/rmse``;
    - ``run_blocks(hyperparams, spec, state, num_blocks) -> (state, metrics)``, metrics
      float[num_blocks * eval_every] with ``eval/return`` (and, where DWBC is compiled,
      ``dwbc_evaluation``'s ``dwbc/eval_*``) NaN except at each block's end;
    - ``train(hyperparams, spec, key)``: both, for ``num_iterations``.
    """

    def __init__(self, config: OfflineConfig, env: envs.Env, demos: Demonstrations):
        demos.check_env(env)
        if demos.confidence is None:
            raise ValueError("the offline methods need confidences: give a confidence file")
        num_demos = demos.num_rows if config.num_demos is None else config.num_demos
        if num_demos > demos.num_rows:
            raise ValueError(
                f"num_demos={num_demos} but the demonstrations have only {demos.num_rows} rows"
            )
        self.config, self.env, self.num_demos = config, env, num_demos
        self.policy = GaussianPolicy(env.action_size, config.hidden_sizes)
        self.dwbc = LogDensityDiscriminator(config.dwbc_branch_size, config.dwbc_hidden_size)
        self.iswbc = LogitDiscriminator(config.iswbc_hidden_sizes)
        self.ilid = IlidSelection(config.ilid_hidden_sizes, config.ilid_discriminator_steps,
                                  config.batch_size, config.ilid_union)  # fmt: skip
        if "ilid" in config.components:
            if demos.trajectory_ids is None:
                raise ValueError(
                    "ILID selects rows by the states they lead to, so it needs trajectories: "
                    "these demonstrations have no trajectory ids (the authors' MuJoCo files' "
                    "rows are shuffled); use a made set or the authors' Pendulum file"
                )
            self._successors = jnp.asarray(
                successor_rows(demos.trajectory_ids, config.ilid_rollback)
            )
        self.optimizer = optax.scale_by_adam()
        # Actions as the environment applies them (clipped to its bounds), as the online
        # methods' behaviour cloning and discriminators see them.
        low, high = np.asarray(env.action_low), np.asarray(env.action_high)
        self._inputs = jnp.asarray(demos.clipped(low, high).inputs)
        self._classifier_inputs = jnp.asarray(demos.inputs)
        self._confidence = jnp.asarray(demos.confidence)
        has_mask = demos.labelled is not None
        self._allowed = jnp.asarray(demos.labelled) if has_mask else None

    @property
    def eval_every(self) -> int:
        return self.config.eval_every

    # -- the start ----------------------------------------------------------------------------

    def init(self, hyperparams: OfflineHyperparams, spec: OfflineSpec, key: jax.Array):
        split_key, classifier_key, policy_key, dwbc_key, iswbc_key, eval_key, carry_key = (
            jax.random.split(key, 7)
        )
        split = make_split(
            split_key, self._confidence, self.num_demos, hyperparams.label_ratio,
            hyperparams.noise_std, self._allowed,
        )  # fmt: skip
        inputs = self._inputs[split.indices]
        size = self.env.observation_size
        expert, errors = self._expert_rows(spec, split, classifier_key)
        normalizer = ObservationNormalizer.create(size).update(inputs[:, :size])
        policy_params = self.policy.init(policy_key, jnp.zeros(size))
        fields = {}
        if "dwbc" in self.config.components:
            params = self.dwbc.init(dwbc_key, inputs[0], jnp.zeros(self.env.action_size))
            fields |= {"dwbc_params": params, "dwbc_optimizer_state": self.optimizer.init(params)}
        if "iswbc" in self.config.components:
            params = self.iswbc.init(iswbc_key, inputs[0])
            fields |= {"iswbc_params": params, "iswbc_optimizer_state": self.optimizer.init(params)}
        ilid_metrics = {}
        if "ilid" in self.config.components:
            ilid_key = jax.random.fold_in(iswbc_key, 1)  # the other methods' keys stay as they were
            ilid_fields, ilid_metrics = self._ilid_selection(
                spec, split, expert, normalizer, ilid_key
            )
            fields |= ilid_fields
        state = OfflineState(
            policy_params=policy_params,
            policy_optimizer_state=self.optimizer.init(policy_params),
            normalizer=normalizer,
            demo_rows=split.indices,
            expert_probability=uniform_over(expert),
            other_probability=uniform_over(~expert),
            step=jnp.zeros((), jnp.int32),
            eval_keys=jax.random.split(eval_key, self.config.num_eval_episodes),
            key=carry_key,
            **fields,
        )
        num_expert = expert.sum()
        metrics = {
            "offline/num_expert": num_expert.astype(jnp.float32),
            "offline/expert_true_confidence": jnp.sum(jnp.where(expert, split.true_confidence, 0))
            / jnp.maximum(num_expert, 1),
            **{f"confidence/{name}": value for name, value in errors.items()},
            **ilid_metrics,
        }
        return state, metrics

    def _expert_rows(self, spec: OfflineSpec, split, key):
        """bool[M], the expert set: D_c's rows at confidence >= the threshold and, where the
        spec asks and the classifier is compiled, D_u's rows whose BSC confidence reaches it;
        and the classifier's errors on D_u (NaN without one)."""
        labelled_expert = split.labelled & (split.confidence >= spec.expert_threshold)
        nan = {"mae": jnp.float32(jnp.nan), "rmse": jnp.float32(jnp.nan)}
        if "classifier" not in self.config.components:
            return labelled_expert, nan

        def classify():
            predicted, _, _ = train_classifier(
                self.config.classifier, spec.classifier, self._classifier_inputs[split.indices],
                split.confidence, split.labelled, key,
            )  # fmt: skip
            return predicted

        # Under vmap a cond with a batched predicate runs both branches; alone, only one.
        predicted = jax.lax.cond(spec.classifier_coef > 0, classify, lambda: split.confidence)
        classified = ~split.labelled & (predicted >= spec.expert_threshold)
        expert = labelled_expert | ((spec.classifier_coef > 0) & classified)
        errors = confidence_errors(predicted, split.true_confidence, split.labelled)
        return expert, jax.tree.map(
            lambda e, n: jnp.where(spec.classifier_coef > 0, e, n), errors, nan
        )

    # -- ILID's selection, before the policy learns ------------------------------------------

    def _ilid_selection(self, spec: OfflineSpec, split, expert, normalizer, key):
        """ILID's two phases on the split (``offline_ilid.IlidSelection.select``): the state's
        ILID fields and the selection's metrics."""
        size = self.env.observation_size
        inputs = self._inputs[split.indices]
        rows = jnp.concatenate([normalizer(inputs[:, :size]), inputs[:, size:]], -1)
        observations = normalizer(self._inputs[:, :size])  # every row's state, the split's or not
        fields, metrics, _ = self.ilid.select(
            spec, rows, observations, self._successors[split.indices], expert,
            split.true_confidence, key,
        )  # fmt: skip
        return fields, metrics

    # -- one gradient step --------------------------------------------------------------------

    def _batch(self, state: OfflineState, probability, key) -> jax.Array:
        """float[B, O + A]: rows drawn with replacement, observations normalised."""
        return self._batch_rows(state, probability, key)[1]

    def _batch_rows(self, state: OfflineState, probability, key):
        """(int[B] the split rows drawn with replacement, float[B, O + A] their inputs with
        observations normalised)."""
        rows = jax.random.choice(key, self.num_demos, (self.config.batch_size,), p=probability)
        return rows, self._split_inputs(state, rows)

    def _split_inputs(self, state: OfflineState, rows) -> jax.Array:
        """float[R, O + A]: the inputs of the split's ``rows`` int[R], observations
        normalised."""
        inputs = self._inputs[state.demo_rows[rows]]
        size = self.env.observation_size
        return jnp.concatenate([state.normalizer(inputs[:, :size]), inputs[:, size:]], -1)

    def _log_density(self, params, batch) -> jax.Array:
        """float[B, A]: the policy's per-dimension log-density of the batch's actions."""
        size = self.env.observation_size
        mean, log_std = self.policy.apply(params, batch[:, :size])
        return gaussian_log_density(mean, log_std, batch[:, size:])

    def _step(self, spec: OfflineSpec, state: OfflineState):
        """One gradient step of every compiled part: the batches, the discriminators' losses
        at their current parameters (their outputs fixed for the policy), the policy's loss;
        then each Adam step (DWBC's discriminator on every ``dwbc_discriminator_every``-th
        step only). The policy stops once ``spec.num_gradient_steps`` are taken."""
        key, expert_key, other_key, union_key, penalty_key, ilid_key = jax.random.split(
            state.key, 6
        )
        expert = self._batch(state, state.expert_probability, expert_key)
        other = self._batch(state, state.other_probability, other_key)
        union = self._batch(state, jnp.full(self.num_demos, 1.0 / self.num_demos), union_key)
        step = state.step + 1
        fields, metrics, fixed = {}, {}, {}
        if "dwbc" in self.config.components:
            (fields, metrics, fixed) = self._dwbc_update(spec, state, expert, other, step)
        if "iswbc" in self.config.components:
            iswbc_fields, iswbc_metrics, weights = self._iswbc_update(
                spec, state, expert, union, penalty_key
            )
            fields |= iswbc_fields
            metrics |= iswbc_metrics
            fixed["iswbc_weights"] = weights
        if "ilid" in self.config.components:
            fixed["ilid"], ilid_metrics = self.ilid_batches(state, ilid_key)
            metrics |= ilid_metrics

        def policy_loss(params):
            return self.policy_loss(spec, params, expert, union, other, fixed)

        grads, policy_metrics = jax.grad(policy_loss, has_aux=True)(state.policy_params)
        params, optimizer_state = adam_step(
            state.policy_params, state.policy_optimizer_state, grads, spec.policy_learning_rate
        )
        learning = state.step < spec.num_gradient_steps
        state = state.replace(
            policy_params=tree_where(learning, params, state.policy_params),
            policy_optimizer_state=tree_where(
                learning, optimizer_state, state.policy_optimizer_state
            ),
            step=step,
            key=key,
            **fields,
        )
        return state, {**metrics, **policy_metrics}

    def ilid_batches(self, state: OfflineState, key):
        """ILID's batches of a step: the selected rows float[B, O + A], the union's
        float[B, O + A] and their weights float[B] (``ilid_union`` "released": each union row
        a zero row with the state's ``ilid_zero_share``, weighted ``ilid_zero_weight``, and
        the step's share of zero rows as ``ilid/union_zero_rows``); and the metrics."""
        selected_key, union_key = jax.random.split(key)
        selected = self._batch(state, state.ilid_selected_probability, selected_key)
        rows, union = self._batch_rows(state, state.ilid_union_probability, union_key)
        weights, metrics = state.ilid_weight[rows], {}
        if self.config.ilid_union == "released":  # its own key: the intended draws unchanged
            zero_key = jax.random.fold_in(union_key, 1)
            union, zero = with_zero_rows(zero_key, union, state.ilid_zero_share)
            weights = jnp.where(zero, state.ilid_zero_weight, weights)
            metrics["ilid/union_zero_rows"] = zero.mean()
        return (selected, union, weights), metrics

    def policy_loss(self, spec: OfflineSpec, params, expert, union, other, fixed):
        """The policy's loss on a step's batches float[B, O + A] each (observations
        normalised): BC on the expert and union rows by the spec's coefficients, plus the
        weighted terms of the parts compiled, their weights held fixed, from ``fixed``:
        ``"dwbc"``: (d on expert, d on other) float[B] each; ``"iswbc_weights"``: float[B]
        on ``union``; ``"ilid"``: (selected rows, union rows float[B, O + A], the union
        rows' weights float[B]); plus weight decay. Returns (loss, metrics)."""
        nll_expert = -self._log_density(params, expert).sum(-1)  # float[B] from here on
        nll_union = -self._log_density(params, union).sum(-1)
        loss = spec.expert_bc_coef * nll_expert.mean() + spec.union_bc_coef * nll_union.mean()
        terms = {"policy/nll_expert": nll_expert.mean(), "policy/nll_union": nll_union.mean()}
        if "dwbc" in fixed:
            nll_other = -self._log_density(params, other).sum(-1)
            dwbc, dwbc_terms = dwbc_policy_loss(
                nll_expert, nll_other, *fixed["dwbc"], spec.dwbc_alpha, spec.dwbc_eta
            )
            loss += spec.dwbc_coef * dwbc
            terms |= dwbc_terms
        if "iswbc_weights" in fixed:
            iswbc, iswbc_terms = weighted_nll(nll_union, fixed["iswbc_weights"], spec.iswbc_cutoff)
            loss += spec.iswbc_coef * iswbc
            terms |= iswbc_terms
        if "ilid" in fixed:  # its codebase: mean_{E+S}[w nll] + mean_S[nll]
            selected, ilid_union, weights = fixed["ilid"]
            nll_selected = -self._log_density(params, selected).sum(-1)
            nll_ilid_union = -self._log_density(params, ilid_union).sum(-1)
            weighted, _ = weighted_nll(nll_ilid_union, weights)
            loss += spec.ilid_coef * (weighted + nll_selected.mean())
            terms |= {"ilid/weighted_nll": weighted, "ilid/nll_selected": nll_selected.mean(),
                      "ilid/mean_weight": weights.mean()}  # fmt: skip
        loss += 0.5 * spec.policy_weight_decay * squared_norm(params)
        return loss, {**terms, "policy/loss": loss}

    def _dwbc_update(self, spec, state: OfflineState, expert, other, step):
        """DWBC's discriminator on (obs, action, the policy's log-density feature): its
        PU loss, an Adam step on every ``dwbc_discriminator_every``-th step, and its d on
        both batches before the step (what the policy's weights read)."""
        feature_expert = log_density_feature(self._log_density(state.policy_params, expert))
        feature_other = log_density_feature(self._log_density(state.policy_params, other))

        def loss_fn(params):
            d_expert = self.dwbc.apply(params, expert, feature_expert)
            d_other = self.dwbc.apply(params, other, feature_other)
            loss, metrics = dwbc_discriminator_loss(d_expert, d_other, spec.dwbc_eta)
            return loss, (metrics, (d_expert, d_other))

        grads, (metrics, outputs) = jax.grad(loss_fn, has_aux=True)(state.dwbc_params)
        grads = jax.tree.map(lambda g: spec.dwbc_coef * g, grads)
        params, optimizer_state = adam_step(
            state.dwbc_params, state.dwbc_optimizer_state, grads, spec.discriminator_learning_rate
        )
        update = step % self.config.dwbc_discriminator_every == 0
        fields = {
            "dwbc_params": tree_where(update, params, state.dwbc_params),
            "dwbc_optimizer_state": tree_where(update, optimizer_state, state.dwbc_optimizer_state),
        }
        return fields, metrics, {"dwbc": outputs}

    def dwbc_evaluation(self, spec: OfflineSpec, state: OfflineState) -> dict:
        """DWBC's discriminator on every row of the split, with the state's policy and
        discriminator (what its next step's weights read), reduced by
        ``offline_losses.dwbc_evaluation_metrics`` (its mean d on E and on O, its mean BC
        weights); float[] each. Rows go through in slices of 1,024."""

        def d_of(row):  # float[O + A] -> float[]
            batch = row[None]
            feature = log_density_feature(self._log_density(state.policy_params, batch))
            return self.dwbc.apply(state.dwbc_params, batch, feature)[0]

        rows = self._split_inputs(state, jnp.arange(self.num_demos))
        d = jax.lax.map(d_of, rows, batch_size=min(self.num_demos, 1024))
        return dwbc_evaluation_metrics(d, state.expert_probability, state.other_probability,
                                       spec.dwbc_alpha, spec.dwbc_eta)  # fmt: skip

    def _iswbc_update(self, spec, state: OfflineState, expert, union, key):
        """ISW-BC's discriminator of the expert batch against the union batch: its logistic
        loss plus the one-centred penalty on g's gradient at points between them, an Adam
        step, and the union rows' importance weights before the step."""
        mix = jax.random.uniform(key, (self.config.batch_size, 1))
        shuffled = jax.random.permutation(jax.random.fold_in(key, 1), union)
        points = jnp.concatenate([mix * expert + (1 - mix) * union,
                                  mix * shuffled + (1 - mix) * union])  # fmt: skip

        def loss_fn(params):
            logits_expert = self.iswbc.apply(params, expert)
            logits_union = self.iswbc.apply(params, union)
            loss, metrics = iswbc_discriminator_loss(logits_expert, logits_union)
            log_odds = jax.vmap(jax.grad(lambda x: iswbc_log_odds(self.iswbc.apply(params, x))))
            penalty = one_centred_penalty(log_odds(points))
            loss = loss + spec.iswbc_penalty_coef * penalty
            # How far apart the weights put the two sets: E's rows against U's mean of 1.
            weight_expert = jnp.mean(iswbc_weights(logits_expert))
            metrics |= {"iswbc/gradient_penalty": penalty, "iswbc/weight_expert": weight_expert}
            return loss, (metrics, logits_union)

        grads, (metrics, logits_union) = jax.grad(loss_fn, has_aux=True)(state.iswbc_params)
        grads = jax.tree.map(lambda g: spec.iswbc_coef * g, grads)
        params, optimizer_state = adam_step(
            state.iswbc_params, state.iswbc_optimizer_state, grads, spec.discriminator_learning_rate
        )
        fields = {"iswbc_params": params, "iswbc_optimizer_state": optimizer_state}
        return fields, metrics, iswbc_weights(logits_union)

    # -- iterations and blocks ----------------------------------------------------------------

    def _iteration(self, spec: OfflineSpec, state: OfflineState):
        """``steps_per_iteration`` gradient steps; their metrics' means."""
        state, metrics = jax.lax.scan(
            lambda s, _: self._step(spec, s), state, None, length=self.config.steps_per_iteration
        )
        metrics = jax.tree.map(lambda m: m.mean(), metrics)
        learned = jnp.minimum(state.step, spec.num_gradient_steps)
        return state, {**metrics, "gradient_steps": learned}

    def run_blocks(
        self, hyperparams: OfflineHyperparams, spec: OfflineSpec, state: OfflineState, num_blocks
    ):
        del hyperparams  # read by ``init`` only (the split)
        eval_every = self.config.eval_every

        def block(state, _):
            state, metrics = jax.lax.scan(
                lambda s, _: self._iteration(spec, s), state, None, length=eval_every
            )
            evaluated = {"eval/return": evaluate(
                self.env, self.policy, state.policy_params, state.normalizer, state.eval_keys
            )}  # fmt: skip
            if "dwbc" in self.config.components:
                evaluated |= self.dwbc_evaluation(spec, state)
            for name, value in evaluated.items():  # NaN between evaluations
                metrics[name] = jnp.full((eval_every,), jnp.nan).at[-1].set(value)
            return state, metrics

        state, metrics = jax.lax.scan(block, state, None, length=num_blocks)
        return state, jax.tree.map(lambda x: x.reshape(-1, *x.shape[2:]), metrics)

    def train(self, hyperparams: OfflineHyperparams, spec: OfflineSpec, key: jax.Array):
        state, init_metrics = self.init(hyperparams, spec, key)
        state, metrics = self.run_blocks(hyperparams, spec, state, self.config.num_evaluations)
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: OfflineState) -> OfflineState:
        """What a policy export reads: ``policy_params`` and ``normalizer``."""
        return state


# -- the methods --------------------------------------------------------------------------------

_DEFAULTS = {field.name: 0.0 for field in dataclasses.fields(OfflineSpec)} | {
    "expert_threshold": 0.5,
    "bsc_eps": 0.01,
    "policy_learning_rate": 3e-4,
    "discriminator_learning_rate": 3e-4,
    "dwbc_alpha": 7.5,
    "dwbc_eta": 0.5,
    "iswbc_penalty_coef": 1.0,
    "ilid_bar": 0.4,
    "ilid_discriminator_learning_rate": 1e-5,
    "ilid_discriminator_weight_decay": 5e-3,
    "num_gradient_steps": float(2**31 - 1),  # every step the grid runs
}

# name: (description, coefficients, components). The settings are each codebase's
# (docs/methods.md): DWBC's Adam at 1e-4 with the policy's coupled weight decay 0.005,
# alpha 7.5, eta 0.5; ISW-BC's Adam at 3e-4, penalty 1, no cut-off; BC at 3e-4.
OFFLINE_PRESETS: dict[str, tuple[str, dict, tuple[str, ...]]] = {
    "bc-expert": ("BC on the expert rows only", {"expert_bc_coef": 1.0}, ()),
    "bc-all": ("BC on every row", {"union_bc_coef": 1.0}, ()),
    "dwbc": ("DWBC: a PU discriminator reading log pi weights BC", {
        "dwbc_coef": 1.0, "policy_learning_rate": 1e-4, "discriminator_learning_rate": 1e-4,
        "policy_weight_decay": 5e-3}, ("dwbc",)),
    "iswbc": ("ISW-BC: BC on every row weighted by D / (1 - D), D expert vs union", {
        "iswbc_coef": 1.0}, ("iswbc",)),
    "ilid": ("ILID: rows leading to expert-like states, weighted BC (needs trajectories)", {
        "ilid_coef": 1.0, "policy_learning_rate": 1e-4, "policy_weight_decay": 5e-3},
        ("ilid",)),
}  # fmt: skip
OFFLINE_METHOD_NAMES = tuple(OFFLINE_PRESETS)
# What experiments.offline runs by default: every method that reads rows alone (ILID needs
# trajectories, which the authors' MuJoCo files do not keep: --methods ...,ilid adds it).
DEFAULT_OFFLINE_METHODS = ("bc-expert", "bc-all", "dwbc", "iswbc")
# A method's variant with the BSC-classified D_u rows in its expert set: "<name>+bsc".
CLASSIFIED_SUFFIX = "+bsc"


def _preset(name: str) -> tuple[dict, tuple[str, ...]]:
    base, classified = name, False
    if name.endswith(CLASSIFIED_SUFFIX):
        base, classified = name.removesuffix(CLASSIFIED_SUFFIX), True
    if base not in OFFLINE_PRESETS:
        raise ValueError(
            f"unknown offline method {name!r}; available: {', '.join(OFFLINE_METHOD_NAMES)}, "
            f"each also as <name>{CLASSIFIED_SUFFIX} (BSC-classified rows join the expert set)"
        )
    _, coefficients, components = OFFLINE_PRESETS[base]
    if classified:
        return {**coefficients, "classifier_coef": 1.0}, (*components, "classifier")
    return coefficients, components


def offline_spec(name: str, **overrides: float) -> OfflineSpec:
    """The offline method ``name`` (``OFFLINE_PRESETS``, or ``<name>+bsc``) as data."""
    coefficients, _ = _preset(name)
    unknown = set(overrides) - set(_DEFAULTS)
    if unknown:
        raise ValueError(f"unknown OfflineSpec field(s) {sorted(unknown)}")
    values = _DEFAULTS | coefficients | overrides
    return OfflineSpec(**{k: jnp.asarray(v, jnp.float32) for k, v in values.items()})


def required_components(methods) -> tuple[str, ...]:
    """The parts (``COMPONENTS``, in that order) that ``methods`` need compiled."""
    needed = {c for name in methods for c in _preset(name)[1]}
    return tuple(c for c in COMPONENTS if c in needed)


def program_groups(methods) -> list[tuple[str, ...]]:
    """``methods`` grouped by the parts they need compiled (``required_components``), in
    order of first appearance: each group is one program, so no cell pays for a part only
    another method reads (a vmapped program computes every part in every cell)."""
    groups: dict[tuple[str, ...], list[str]] = {}
    for name in methods:
        groups.setdefault(required_components([name]), []).append(name)
    return [tuple(group) for group in groups.values()]
