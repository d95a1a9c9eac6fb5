"""The interface between the adversarial trainer and the appendix baselines' training phases.

A phase is one baseline's own training inside the one-program grid: behaviour cloning
(``bc.CloningPhase``), rewards learned from rankings (``ranking.RankingPhase``: T-REX's
``demo_rankings``, D-REX's ``noise_rankings``), f-IRL's outer step (``firl.FirlPhase``) and
CAIL's rounds (``cail.CailPhase``). Each lives in its baseline's module and never sees the
trainer: the trainer gives it a ``PhaseContext`` (what a phase may read) and calls its hooks at
fixed points of an iteration, through a ``PhaseSet``:

1. ``init`` once per cell, after the split and the confidences: the phase's state fields of
   ``TrainState`` (and the learner's state, which behaviour cloning replaces);
2. ``reward`` in every iteration, before any step: a term added to the policy's reward (its
   coefficient is in the cell's ``MethodSpec``), with the phase's new state fields;
3. ``discriminator_step`` after the discriminator's Adam step: CAIL's rounds replace it;
4. ``after_update`` after the learner's update: a cloned policy no RL moves is kept.

A phase that needs none of a hook inherits ``Phase``'s, which changes nothing. Every hook is
pure and jittable; which phases a grid compiles is static (``AdversarialConfig.phases``), and
which cell reads which phase's output is data (the ``MethodSpec`` coefficients).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
from flax import linen as nn

from pngail_jax import envs
from pngail_jax.rl.on_policy import OnPolicyLearner


@dataclasses.dataclass(frozen=True)
class PhaseContext:
    """What a phase may read of the run, built once by the trainer (nothing here changes
    between cells or iterations)."""

    env: envs.Env
    learner: OnPolicyLearner  # the policy learner (``rl.learners.make_learner``): TRPO or PPO
    discriminator: nn.Module  # the adversarial discriminator z(s, a)
    demo_inputs: jax.Array  # float[N, O + A]: every demonstration row, actions clipped
    action_bounds: tuple[jax.Array, jax.Array]  # (low, high), float[A] each
    num_demos: int  # M: rows per split
    num_envs: int  # the rollout's shape: N parallel environments ...
    unroll_length: int  # ... of T steps each
    # The demonstration trajectories ranked by their given confidence (``ranking.Trajectories``)
    # and each row's trajectory index int[N]; None without trajectory ids or confidences.
    trajectories: object | None = None
    row_trajectory: jax.Array | None = None


class InitKeys(NamedTuple):
    """The keys of the phases' ``init``, split once from the cell's phase key (so every
    number of a phase stays the same whichever other phases a grid compiles)."""

    bc: jax.Array
    noise: jax.Array  # D-REX's cloned policy and its noisy rollouts
    reward: jax.Array  # the rewards learned from rankings (T-REX's, D-REX's)
    firl: jax.Array

    @classmethod
    def split(cls, key: jax.Array) -> InitKeys:
        return cls(*jax.random.split(key, 4))


class Phase:
    """A baseline's training phase; its hooks by default change nothing. ``names`` are the
    ``methods.PHASES`` it implements (a grid may compile a subset of them)."""

    names: tuple[str, ...] = ()
    # Whether the phase reads the ranking of demonstration trajectories (``ranked`` in init).
    ranks_demonstrations: bool = False

    def init(self, context: PhaseContext, spec, inputs, confidence, learner_state, keys, ranked):
        """(TrainState fields, learner_state) of one cell: ``inputs`` float[M, O + A] are the
        split's rows, ``confidence`` float[M] their r, ``ranked`` bool[K] the trajectories
        whose ranking the cell may see (None when no compiled phase ranks them)."""
        return {}, learner_state

    def reward(self, context: PhaseContext, spec, state, transitions, batch, key):
        """(reward term float[B] or None, new TrainState fields, metrics) of one iteration,
        before any step; ``batch`` is the trainer's ``DiscriminatorBatch``."""
        return None, {}, {}

    def discriminator_step(self, context: PhaseContext, spec, state, batch, key, stepped):
        """``stepped`` = (params, Adam state, metrics) after the discriminator's step; returns
        them (replaced where the phase trains the discriminator itself), new TrainState
        fields and metrics."""
        return stepped, {}, {}

    def after_update(self, context: PhaseContext, spec, before, updated):
        """The learner's state after its update (``before``: the state that was updated)."""
        return updated


class PhaseSet:
    """The phases a trainer compiles, called in their order (``methods.PHASES``)."""

    def __init__(self, context: PhaseContext, phases: tuple[Phase, ...]):
        self.context = context
        self.phases = phases
        self.names = tuple(name for phase in phases for name in phase.names)

    def __bool__(self) -> bool:
        return bool(self.phases)

    def get(self, kind: type) -> Phase | None:
        """The compiled phase of class ``kind``, or None."""
        return next((phase for phase in self.phases if isinstance(phase, kind)), None)

    def init(self, spec, inputs, confidence, learner_state, key, label_ratio):
        """(TrainState fields, learner_state) of the cell of ``key`` (its own key: the phases
        draw from ``fold_in``s of it): every phase's, and ``ranked_trajectories`` when a
        phase ranks the demonstrations."""
        fields, ranked = {}, None
        trajectories = self.context.trajectories
        if trajectories is not None and any(p.ranks_demonstrations for p in self.phases):
            num = trajectories.lengths.shape[0]
            ranked = ranked_trajectories(num, label_ratio, jax.random.fold_in(key, 2))
            fields["ranked_trajectories"] = ranked
        keys = InitKeys.split(jax.random.fold_in(key, 1))
        for phase in self.phases:
            more, learner_state = phase.init(
                self.context, spec, inputs, confidence, learner_state, keys, ranked
            )
            fields |= more
        return fields, learner_state

    def reward(self, spec, state, transitions, batch, rewards, key):
        """``rewards`` float[B] plus every phase's term; (rewards, fields, metrics)."""
        fields, metrics = {}, {}
        for phase in self.phases:
            term, more_fields, more_metrics = phase.reward(
                self.context, spec, state, transitions, batch, key
            )
            if term is not None:
                rewards += term
            fields, metrics = fields | more_fields, metrics | more_metrics
        return rewards, fields, metrics

    def discriminator_step(self, spec, state, batch, key, stepped):
        fields, metrics = {}, {}
        for phase in self.phases:
            stepped, more_fields, more_metrics = phase.discriminator_step(
                self.context, spec, state, batch, key, stepped
            )
            fields, metrics = fields | more_fields, metrics | more_metrics
        return stepped, fields, metrics

    def after_update(self, spec, before, updated):
        for phase in self.phases:
            updated = phase.after_update(self.context, spec, before, updated)
        return updated


def ranked_trajectories(num_trajectories: int, label_ratio, key) -> jax.Array:
    """bool[K]: a share ``label_ratio`` of the K demonstration trajectories (rounded, at
    least 2), drawn per seed, whose ranking T-REX and CAIL may see: the same label
    information as the ``label_ratio`` of rows PN-GAIL's D_c holds."""
    num_ranked = jnp.maximum(jnp.round(label_ratio * num_trajectories), 2)
    position = jax.random.permutation(key, num_trajectories)
    return (
        jnp.zeros(num_trajectories, bool)
        .at[position]
        .set(jnp.arange(num_trajectories) < num_ranked)
    )
