"""``PolicyTrainer``: TRPO (or another learner) on a fixed reward as one pure program, so
``jax.jit(jax.vmap(PolicyTrainer(config, env).train))(stacked_hyperparams, keys)`` trains many
runs in one program."""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
from flax import struct

from pngail_jax import envs
from pngail_jax.rl.on_policy import OnPolicyLearner, RolloutConfig, run_evaluated_blocks
from pngail_jax.rl.rollout import Transitions
from pngail_jax.rl.trpo import TRPO, TRPOHyperparams, TRPOState

RewardFunction = Callable[[Transitions], jax.Array]


def true_reward(transitions: Transitions) -> jax.Array:
    return transitions.reward


@struct.dataclass
class PolicyTrainState:
    """A TRPO-only run's state: the learner plus its fixed evaluation episode keys."""

    learner: TRPOState  # or another learner's state (PPOState)
    eval_keys: jax.Array  # key[num_eval_episodes], the same every evaluation


class PolicyTrainer:
    """TRPO (or another ``learner``, e.g. ``rl.PPO``) on a fixed reward (the environment's by
    default), in blocks.

    The trainer interface shared with ``pngail_jax.adversarial.trainer.AdversarialTrainer``
    (and used by ``pngail_jax.grid.Grid``): ``init(*cell_inputs, key) -> (state, init_metrics)``,
    ``run_blocks(*cell_inputs, state, num_blocks) -> (state, metrics)`` and
    ``train(*cell_inputs, key)``, their composition. Here the cell inputs are one
    ``TRPOHyperparams`` (the learner's: ``PPOHyperparams`` for PPO). All three are pure and
    jittable; ``num_blocks`` is static.

    ``metrics`` map names to float[num_blocks * eval_every]; ``eval/return`` (the
    deterministic policy on ``num_eval_episodes`` fixed-key episodes) is set at the end of
    each block of ``eval_every`` iterations and NaN elsewhere; ``rollout/nonfinite_actions``
    counts each iteration's steps that applied a NaN or inf action (0 in a healthy run).
    """

    def __init__(
        self,
        config: RolloutConfig,
        env: envs.Env,
        reward_fn: RewardFunction = true_reward,
        learner: OnPolicyLearner | None = None,
    ):
        self.config = config
        self.env = env
        self.learner = TRPO(config, env) if learner is None else learner
        if self.learner.config != config:
            raise ValueError("PolicyTrainer: the learner was built with another RolloutConfig")
        self.reward_fn = reward_fn

    @property
    def eval_every(self) -> int:
        """Iterations per block of ``run_blocks`` (``grid.Trainer``)."""
        return self.config.eval_every

    def init(self, hyperparams: TRPOHyperparams, key: jax.Array):
        self.learner.check_hyperparams(hyperparams)  # init reads none, but the blocks will
        init_key, eval_key = jax.random.split(key)
        state = PolicyTrainState(
            learner=self.learner.init(init_key),
            eval_keys=jax.random.split(eval_key, self.config.num_eval_episodes),
        )
        return state, {}

    def _iteration(self, hyperparams: TRPOHyperparams, state: TRPOState):
        state, transitions = self.learner.rollout(state)
        rewards = self.reward_fn(transitions)
        state, metrics = self.learner.update(hyperparams, state, transitions, rewards)
        return state, {**metrics, "env_steps": state.env_steps}

    def run_blocks(
        self, hyperparams: TRPOHyperparams, state: PolicyTrainState, num_blocks: int
    ) -> tuple[PolicyTrainState, dict]:
        learner_state, metrics = run_evaluated_blocks(
            self.learner,
            functools.partial(self._iteration, hyperparams),
            state.learner,
            lambda s: s,
            state.eval_keys,
            num_blocks,
        )
        return state.replace(learner=learner_state), metrics

    def train(self, hyperparams: TRPOHyperparams, key: jax.Array):
        state, init_metrics = self.init(hyperparams, key)
        state, metrics = self.run_blocks(hyperparams, state, self.config.num_evaluations)
        return state, {**metrics, **init_metrics}

    @staticmethod
    def policy_state(state: PolicyTrainState) -> TRPOState:
        """The learner's state inside a trainer state (for exporting its policy)."""
        return state.learner
