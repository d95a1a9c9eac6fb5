"""Where one adversarial-training iteration spends its time, phase by phase, for a grid of cells.

Builds an ``AdversarialTrainer`` on synthetic demonstrations and ``--cells`` cells (PN-GAIL's
``MethodSpec``, ``AdversarialHyperparams`` defaults, one seed each, initialised by the trainer)
with the environment's run settings (``pngail_jax.config.settings.settings_for``:
parallel envs, unroll length, MJX solver, evaluation episodes; flags override the shape),
initialises their TRPO states and runs a real rollout, so every phase sees realistic inputs.
Each phase is then its own program, ``jax.jit(jax.vmap(phase))`` over the cells as in the real
grid, compiled ahead of time (compile seconds = lower + compile) and called twice. Then all
phases are timed warm in ``--rounds`` (5) interleaved rounds, every phase once per round, so
that a change of load on a shared machine hits all phases alike; a round's sample of a phase
is the mean of back-to-back calls (each ended by ``block_until_ready``) lasting at least
``SAMPLE_SECONDS``, and a phase's milliseconds are the median over rounds. Phases, in the
order of ``pngail_jax.adversarial.trainer.AdversarialTrainer``'s iteration:

- ``rollout``: ``trpo.rollout``, the ``unroll_length``-step ``lax.scan`` over the envs.
- ``importance_weights``: WGAIL's w on every split row (``--demo-rows``).
  ``adversarial/trainer.py`` puts it in a ``jnp.where`` with its refresh schedule, so it is
  computed every iteration.
- ``discriminator``: the trainer's own steps: its batch (the agent rows and as many
  demonstration rows drawn with replacement; random rows: the cost does not depend on their
  values), the gradient of PN-GAIL's loss, the policy's reward and the Adam step.
- ``values``: observation normalisation and the value network on ``obs`` and ``final_obs``.
- ``gae/sequential``, ``gae/associative``: ``generalized_advantages`` as ``trpo.update`` calls
  it (both lambdas in one pass), in each form. ``gae/sequential_unrollK`` is a benchmark-only
  copy of the sequential recurrence with ``lax.scan(..., unroll=K)``, K in ``UNROLLS`` below
  the unroll length (fully unrolled, Pendulum's 200 steps took a minute to compile and ran
  13x slower on a 2-core CPU); the run checks it against the library's numbers first.
- ``value_fit``: ``trpo.fit_value``, ``num_value_minibatches`` dependent Adam steps.
- ``conjugate_gradient``: ``num_cg_iterations`` dependent products with the Fisher product of
  ``--fisher`` (its set-up included: for Gauss-Newton, the policy's linearisation).
- ``line_search``: ``backtracking_line_search`` on the natural-gradient step of these inputs:
  up to ``num_backtracks`` fractions in order, stopping at the first it takes.
  ``line_search/all_fractions`` is a benchmark-only copy of the library's earlier form, every
  fraction evaluated side by side (a vmap) and the first acceptable one picked; the run
  checks that both take the same step first.
- ``update``: the whole ``trpo.update``; ``iteration``: ``AdversarialTrainer._iteration``
  itself (rollout, importance weights, discriminator step and update).
- ``evaluation``: ``trpo.evaluate`` on ``num_eval_episodes`` episodes; it stops once every
  episode has ended, so with a fresh policy a task that terminates (Ant, Hopper, Walker2d)
  costs little. ``evaluation/no_termination`` times it on the same task built with
  ``terminate_when_unhealthy=False``: the full ``max_episode_steps`` a good policy costs.
  An evaluation runs once per ``eval_every`` iterations; the run prints its amortised share.

``share_of_iteration`` divides a phase's milliseconds by the ``iteration`` row's. The summary
answers: is the associative GAE faster than the sequential one here, and how much of an
iteration do the sequential chains (rollout scan, GAE, value minibatches, CG) and the line
search take.

    python benchmarks/iteration_phases.py                              # Pendulum-v1, 7 cells
    python benchmarks/iteration_phases.py --env Hopper --cells 1       # MJX compiles: minutes
    python benchmarks/iteration_phases.py --env Hopper --fisher hessian --json rows.json

Row schema: ``{name, env, phase, cells, num_envs, unroll_length, milliseconds,
share_of_iteration, compile_seconds, device, jax_version}`` plus ``fisher`` and ``gae_form``
(the form ``update`` and ``iteration`` use); ``milliseconds`` is one call for all cells.
"""

from __future__ import annotations

import argparse
import functools
import math
import statistics
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from common import context, markdown_table, write_rows
from flax import struct

from pngail_jax import envs
from pngail_jax.adversarial.methods import method_spec, stack
from pngail_jax.adversarial.trainer import (
    AdversarialConfig,
    AdversarialHyperparams,
    AdversarialTrainer,
)
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.learner import DEFAULT_FISHER, FISHER_FORMS, LearnerConfig
from pngail_jax.config.settings import describe, make_env, settings_for
from pngail_jax.demos import Demonstrations
from pngail_jax.fitting import adam_step
from pngail_jax.rl.gae import generalized_advantages
from pngail_jax.rl.trpo import (
    TRPO,
    TRPOConfig,
    backtracking_line_search,
    conjugate_gradient,
)

NUM_ROUNDS = 5
SAMPLE_SECONDS = 0.05  # fast phases: back-to-back calls per sample, each blocked, to last this
MAX_CALLS_PER_SAMPLE = 100
UNROLLS = (2, 4, 8)
TERMINATING_ENVS = ("Ant", "Hopper", "Walker2d", "Ant-v4", "Hopper-v4", "Walker2d-v4")
CHAIN_PHASES = ("rollout", "gae/sequential", "value_fit", "conjugate_gradient")


@struct.dataclass
class PolicyBatch:
    """``trpo.update``'s flattened inputs to the value fit and the policy step: [T * N, ...]."""

    obs: jax.Array  # normalised
    actions: jax.Array
    log_prob: jax.Array
    advantages: jax.Array  # standardised
    targets: jax.Array


def unrolled_sequential_advantages(
    rewards, values, next_values, done, truncated, gamma, lam, bootstrap_truncation, unroll
):
    """BENCHMARK VARIANT, not used in training: ``generalized_advantages(form="sequential")``
    for lam float[K], copied with ``lax.scan(..., unroll=unroll)``. Returns float[K, T, N]."""
    finished = done | truncated
    terminal = jnp.where(bootstrap_truncation, done, finished)
    deltas = rewards + gamma * jnp.where(terminal, 0.0, next_values) - values
    continues = 1.0 - finished.astype(rewards.dtype)
    decay = gamma * lam[None, :, None] * continues[:, None, :]  # [T, K, N]: time leads
    deltas = jnp.broadcast_to(deltas[:, None, :], decay.shape)

    def backward(next_advantage, inputs):
        delta, step_decay = inputs
        advantage = delta + step_decay * next_advantage
        return advantage, advantage

    _, advantages = jax.lax.scan(
        backward, jnp.zeros_like(deltas[0]), (deltas, decay), reverse=True, unroll=unroll
    )
    advantages = jnp.moveaxis(advantages, 0, 1)
    return advantages, advantages + values


def advantages_and_targets(
    hyperparams, transitions, rewards, values, next_values, form="sequential", unroll=None
):
    """GAE as ``trpo.update`` calls it: advantages (lam) and targets (lambda 1) in one pass.

    ``unroll`` set: the benchmark copy of the sequential form with that scan unroll.
    """
    trpo_hyperparams = hyperparams.learner
    arguments = (
        rewards,
        values,
        next_values,
        transitions.done,
        transitions.truncated,
        trpo_hyperparams.gamma,
        jnp.stack([trpo_hyperparams.lam, jnp.ones_like(trpo_hyperparams.lam)]),
        trpo_hyperparams.bootstrap_truncation,
    )
    if unroll is None:
        return generalized_advantages(*arguments, form)
    return unrolled_sequential_advantages(*arguments, unroll)


class Phases:
    """The phases of one cell's adversarial iteration, each a pure function to vmap over cells:
    the real ``AdversarialTrainer``'s named steps (PN-GAIL, ``num_demo_rows`` synthetic
    demonstration rows) and TRPO's public steps, timed one by one."""

    def __init__(self, trpo: TRPO, num_demo_rows: int):
        self.trpo = trpo
        self.config = trpo.config
        env = trpo.env
        rng = np.random.default_rng(0)
        demos = Demonstrations(
            observations=rng.normal(size=(num_demo_rows, env.observation_size)).astype("f4"),
            actions=rng.uniform(
                env.action_low, env.action_high, (num_demo_rows, env.action_size)
            ).astype("f4"),
            confidence=rng.uniform(size=num_demo_rows).astype("f4"),
        )
        # The split holds every row; a short classifier phase (only init uses it).
        self.trainer = AdversarialTrainer(
            AdversarialConfig(
                rollout=self.config,
                learner=LearnerConfig(trpo=trpo.trpo),
                classifier=ClassifierConfig(num_steps=10),
                num_demos=num_demo_rows,
            ),
            env,
            demos,
        )

    def init(self, hyperparams, spec, key):
        """A trainer state after ``init`` (split, classifier, TRPO and discriminator)."""
        return self.trainer.init(hyperparams, spec, key)[0]

    def importance_weights(self, state) -> jax.Array:
        """WGAIL's w on every split row (``AdversarialTrainer.importance_weights``)."""
        return self.trainer.importance_weights(state)

    def discriminator_step(self, hyperparams, spec, state, transitions):
        """The trainer's discriminator batch, gradient and Adam step, and the policy's reward
        float[T, N] from the discriminator before the step: (params, rewards)."""
        trainer = self.trainer
        key = jax.random.fold_in(state.key, 0)
        batch = trainer.discriminator_batch(state, transitions, key)
        grads, _, logits_agent = trainer.discriminator_gradient(
            spec, state, batch, state.importance_weights
        )
        rewards, _, _ = trainer.policy_rewards(spec, state, transitions, batch, logits_agent, key)
        params, _ = adam_step(
            state.discriminator_params,
            state.discriminator_optimizer_state,
            grads,
            hyperparams.discriminator_learning_rate,
        )
        return params, rewards

    def values(self, state, transitions):
        """``trpo.update``'s normalisation and value predictions: (normalizer, obs, values,
        next_values), obs float[T, N, O], values float[T, N]."""
        normalizer = state.normalizer
        if self.config.normalize_observations:
            normalizer = normalizer.update(transitions.obs)
        obs = normalizer(transitions.obs)
        values = self.trpo.value.apply(state.value_params, obs)
        next_values = self.trpo.value.apply(state.value_params, normalizer(transitions.final_obs))
        return normalizer, obs, values, next_values

    def policy_batch(self, hyperparams, state, transitions, rewards):
        """``trpo.update``'s first step (``TRPO.advantages_and_targets``), flattened as the
        value fit and the policy step take it (not timed)."""
        targets = self.trpo.advantages_and_targets(hyperparams.learner, state, transitions, rewards)

        def flat(x):
            return x.reshape(self.config.batch_size, *x.shape[2:])

        return PolicyBatch(
            obs=flat(targets.obs),
            actions=flat(transitions.action),
            log_prob=flat(transitions.log_prob),
            advantages=flat(targets.advantages),
            targets=flat(targets.value_targets),
        )

    def fit_value(self, hyperparams, state, batch: PolicyBatch):
        return self.trpo.fit_value(hyperparams.learner, state, batch.obs, batch.targets, state.key)

    def policy_problem(self, hyperparams, state, batch: PolicyBatch):
        """``TRPO.policy_objective`` at the current parameters:
        ``(flat_params, surrogate_loss, fisher_vector_product)``."""
        objective = self.trpo.policy_objective(
            hyperparams.learner,
            state.policy_params,
            batch.obs,
            batch.actions,
            batch.log_prob,
            batch.advantages,
        )
        return objective.flat_params, objective.surrogate_loss, objective.fisher_vector_product

    def loss_gradient(self, hyperparams, state, batch: PolicyBatch):
        flat_params, surrogate_loss, _ = self.policy_problem(hyperparams, state, batch)
        return jax.grad(surrogate_loss)(flat_params)

    def conjugate_gradient(self, hyperparams, state, batch: PolicyBatch, loss_gradient):
        _, _, product = self.policy_problem(hyperparams, state, batch)
        return conjugate_gradient(product, -loss_gradient, self.trpo.trpo.num_cg_iterations)

    def full_step(self, hyperparams, state, batch: PolicyBatch, loss_gradient, direction):
        """``natural_gradient_step``'s scaling of the CG direction to the KL bound:
        ``(full_step, expected_improvement)``."""
        _, _, product = self.policy_problem(hyperparams, state, batch)
        step_size_squared = 0.5 * jnp.vdot(direction, product(direction))
        multiplier = jnp.sqrt(jnp.maximum(step_size_squared, 1e-30) / hyperparams.learner.max_kl)
        return direction / multiplier, jnp.vdot(-loss_gradient, direction) / multiplier

    def line_search(self, hyperparams, state, batch, full_step, expected_improvement):
        flat_params, surrogate_loss, _ = self.policy_problem(hyperparams, state, batch)
        return backtracking_line_search(
            surrogate_loss,
            flat_params,
            full_step,
            expected_improvement,
            self.trpo.trpo.num_backtracks,
        )

    def line_search_all_fractions(self, hyperparams, state, batch, full_step, expected):
        """The earlier line search: every fraction's loss side by side, the first acceptable
        taken (the same result as ``line_search``)."""
        flat_params, surrogate_loss, _ = self.policy_problem(hyperparams, state, batch)
        fractions = 0.5 ** jnp.arange(self.trpo.trpo.num_backtracks, dtype=flat_params.dtype)
        losses = jax.vmap(lambda f: surrogate_loss(flat_params + f * full_step))(fractions)
        actual = surrogate_loss(flat_params) - losses
        acceptable = (actual / (expected * fractions) > 0.1) & (actual > 0)
        accepted = jnp.any(acceptable)
        fraction = jnp.where(accepted, fractions[jnp.argmax(acceptable)], 0.0)
        return flat_params + fraction * full_step, accepted, fraction

    def update(self, hyperparams, state, transitions, rewards):
        return self.trpo.update(hyperparams.learner, state, transitions, rewards)

    def iteration(self, hyperparams, spec, state):
        """``AdversarialTrainer._iteration`` itself."""
        return self.trainer.iteration(hyperparams, spec, state)


class PhaseTimer:
    """Compiles ``jit(vmap(function))`` per phase ahead of time, then times all phases in
    interleaved rounds, so that a change of load on a shared machine hits every phase alike."""

    def __init__(self):
        self.programs: dict[str, tuple] = {}  # phase -> (compiled, arguments, calls per sample)
        self.compile_seconds: dict[str, float] = {}

    def compile(self, phase: str, function, *arguments):
        """Compiles ``function`` vmapped over the leading (cell) axis of every argument, runs it
        twice (the second call sets how many calls make one sample); returns its outputs."""
        start = time.perf_counter()
        compiled = jax.jit(jax.vmap(function)).lower(*arguments).compile()
        self.compile_seconds[phase] = time.perf_counter() - start
        outputs = jax.block_until_ready(compiled(*arguments))
        start = time.perf_counter()
        jax.block_until_ready(compiled(*arguments))
        seconds = time.perf_counter() - start
        calls = min(MAX_CALLS_PER_SAMPLE, max(1, math.ceil(SAMPLE_SECONDS / seconds)))
        self.programs[phase] = (compiled, arguments, calls)
        print(f"  compiled {phase:32s} {self.compile_seconds[phase]:6.1f} s", flush=True)
        return outputs

    def time_all(self, num_rounds: int) -> dict[str, dict[str, float]]:
        """Milliseconds per call (median over rounds of each round's mean) and compile
        seconds, by phase."""
        samples = {phase: [] for phase in self.programs}
        for _ in range(num_rounds):
            for phase, (compiled, arguments, calls) in self.programs.items():
                start = time.perf_counter()
                for _ in range(calls):
                    jax.block_until_ready(compiled(*arguments))
                samples[phase].append((time.perf_counter() - start) / calls)
        return {
            phase: {
                "milliseconds": 1000 * statistics.median(samples[phase]),
                "compile_seconds": self.compile_seconds[phase],
            }
            for phase in self.programs
        }


def compile_gae(timer, phases, hyperparams, transitions, rewards, values, next_values):
    """GAE in both library forms, and the unrolled benchmark copies, checked against the
    library's sequential numbers."""
    arguments = (hyperparams, transitions, rewards, values, next_values)
    outputs = {
        form: timer.compile(
            f"gae/{form}", functools.partial(advantages_and_targets, form=form), *arguments
        )
        for form in ("sequential", "associative")
    }
    unroll_length = phases.config.unroll_length
    for unroll in (u for u in UNROLLS if u < unroll_length):
        function = functools.partial(advantages_and_targets, unroll=unroll)
        copy = jax.jit(jax.vmap(function))(*arguments)
        for copy_part, reference_part in zip(copy, outputs["sequential"], strict=True):
            scale = jnp.abs(reference_part).max()
            if not jnp.allclose(copy_part, reference_part, rtol=1e-4, atol=1e-4 * scale):
                raise AssertionError(f"unroll={unroll}: the benchmark copy of GAE disagrees")
        timer.compile(f"gae/sequential_unroll{unroll}", function, *arguments)


def compile_phases(phases: Phases, evaluation_trpo: TRPO | None, cells: int, key) -> PhaseTimer:
    """Compiles every phase in the iteration's order, each fed the outputs of the phases
    before it (a real rollout's transitions, the discriminator's rewards, ...)."""
    trpo, config = phases.trpo, phases.config
    init_key, evaluation_key = jax.random.split(key)
    hyperparams = stack([AdversarialHyperparams.create()] * cells)
    spec = stack([method_spec("pngail")] * cells)
    trainer_state = jax.jit(jax.vmap(phases.init))(
        hyperparams, spec, jax.random.split(init_key, cells)
    )
    state = trainer_state.learner
    evaluation_keys = jax.random.split(evaluation_key, (cells, config.num_eval_episodes))
    timer = PhaseTimer()

    after_rollout, transitions = timer.compile("rollout", trpo.rollout, state)
    timer.compile("importance_weights", phases.importance_weights, trainer_state)
    _, rewards = timer.compile(
        "discriminator", phases.discriminator_step, hyperparams, spec, trainer_state, transitions
    )
    _, _, values, next_values = timer.compile("values", phases.values, after_rollout, transitions)
    compile_gae(timer, phases, hyperparams, transitions, rewards, values, next_values)
    batch = jax.jit(jax.vmap(phases.policy_batch))(hyperparams, after_rollout, transitions, rewards)
    timer.compile("value_fit", phases.fit_value, hyperparams, after_rollout, batch)
    loss_gradient = jax.jit(jax.vmap(phases.loss_gradient))(hyperparams, after_rollout, batch)
    direction = timer.compile(
        "conjugate_gradient",
        phases.conjugate_gradient,
        hyperparams,
        after_rollout,
        batch,
        loss_gradient,
    )
    full_step, expected_improvement = jax.jit(jax.vmap(phases.full_step))(
        hyperparams, after_rollout, batch, loss_gradient, direction
    )
    searched = [
        timer.compile(name, function, hyperparams, after_rollout, batch, full_step,
                      expected_improvement)
        for name, function in (("line_search", phases.line_search),
                               ("line_search/all_fractions", phases.line_search_all_fractions))
    ]  # fmt: skip
    if not all(jnp.array_equal(a, b) for a, b in zip(*searched, strict=True)):
        raise AssertionError("the two line searches took different steps")
    timer.compile("update", phases.update, hyperparams, after_rollout, transitions, rewards)
    timer.compile("iteration", phases.iteration, hyperparams, spec, trainer_state)
    timer.compile("evaluation", trpo.evaluate, after_rollout, evaluation_keys)
    if evaluation_trpo is not None:
        timer.compile(
            "evaluation/no_termination", evaluation_trpo.evaluate, after_rollout, evaluation_keys
        )
    return timer


def make_rows(results: dict[str, dict[str, float]], common: dict) -> list[dict]:
    iteration_milliseconds = results["iteration"]["milliseconds"]
    return [
        {
            "name": "iteration_phases",
            "env": common["env"],
            "phase": phase,
            **common,
            **result,
            "share_of_iteration": result["milliseconds"] / iteration_milliseconds,
        }
        for phase, result in results.items()
    ]


def rows_table(rows: list[dict]) -> str:
    header = ["phase", f"ms per call ({rows[0]['cells']} cells)", "share of iteration", "compile s"]
    cells = [
        [row["phase"], f"{row['milliseconds']:,.3f}", f"{row['share_of_iteration']:.2%}",
         f"{row['compile_seconds']:.1f}"]
        for row in rows
    ]  # fmt: skip
    return markdown_table(header, cells, "lrrr")


def summary(rows: list[dict], eval_every: int) -> str:
    """The GAE verdict, the sequential chains' shares and the evaluation's amortised share."""
    by_phase = {row["phase"]: row for row in rows}
    sequential = by_phase["gae/sequential"]["milliseconds"]
    associative = by_phase["gae/associative"]["milliseconds"]
    verdict = "faster" if associative < sequential else "slower"
    unrolled = {p: r for p, r in by_phase.items() if p.startswith("gae/sequential_unroll")}
    fastest = min(unrolled, key=lambda phase: unrolled[phase]["milliseconds"])
    chain_shares = [(phase, by_phase[phase]["share_of_iteration"]) for phase in CHAIN_PHASES]
    chains = ", ".join(f"{phase} {share:.1%}" for phase, share in chain_shares)
    lines = [
        f"GAE: associative {associative:.3f} ms vs sequential {sequential:.3f} ms: the "
        f"associative form is {sequential / associative:.2f}x the sequential one's speed "
        f"({verdict}); fastest unrolled copy {fastest} "
        f"{unrolled[fastest]['milliseconds']:.3f} ms; GAE is "
        f"{by_phase['gae/sequential']['share_of_iteration']:.2%} of the iteration.",
        f"Sequential chains: {chains}; together "
        f"{sum(share for _, share in chain_shares):.1%} of the iteration; line search "
        f"{by_phase['line_search']['share_of_iteration']:.1%} (every fraction side by side, "
        f"as before: {by_phase['line_search/all_fractions']['share_of_iteration']:.1%}).",
    ]
    for phase in ("evaluation", "evaluation/no_termination"):
        if phase in by_phase:
            lines.append(
                f"{phase}: once per {eval_every} iterations, "
                f"{by_phase[phase]['share_of_iteration'] / eval_every:.1%} of an iteration "
                "amortised."
            )
    return "\n".join(lines)


def parse_arguments(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", choices=envs.ENV_NAMES, default="Pendulum-v1")
    parser.add_argument("--cells", type=int, default=7, help="grid cells, vmapped (default 7)")
    parser.add_argument("--num-envs", type=int, help="parallel envs per cell (default: settings)")
    parser.add_argument("--unroll-length", type=int, help="steps per env (default: settings)")
    parser.add_argument("--fisher", choices=FISHER_FORMS, default=DEFAULT_FISHER)
    parser.add_argument(
        "--gae-form",
        choices=("sequential", "associative"),
        default="sequential",
        help="the GAE form of the update and iteration rows (the GAE rows time both)",
    )
    parser.add_argument(
        "--demo-rows", type=int, default=1000, help="split rows M (the Pendulum set's 1,000)"
    )
    parser.add_argument(
        "--rounds", type=int, default=NUM_ROUNDS, help="timing rounds over all phases"
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", type=Path, default=None, help="write the rows here")
    args = parser.parse_args(argv)
    for name in ("cells", "num_envs", "unroll_length", "demo_rows", "rounds"):
        value = getattr(args, name)
        if value is not None and value < 1:
            parser.error(f"--{name.replace('_', '-')} must be a positive integer, got {value}")
    return args


def main(argv=None) -> None:
    args = parse_arguments(argv)
    settings = settings_for(args.env, num_envs=args.num_envs, unroll_length=args.unroll_length)
    config = settings.rollout_config(num_iterations=settings.eval_every, gae_form=args.gae_form)
    trpo_config = TRPOConfig(fisher=args.fisher)
    trpo = TRPO(config, make_env(args.env, settings), trpo_config)
    evaluation_trpo = None
    if args.env in TERMINATING_ENVS:
        options = dict(settings.env_options)
        if args.env in envs.GYM_TASKS:
            options["physics"] = settings.physics
        never_ending = envs.make(args.env, terminate_when_unhealthy=False, **options)
        evaluation_trpo = TRPO(config, never_ending, trpo_config)
    common = {
        "env": args.env,
        "cells": args.cells,
        "num_envs": config.num_envs,
        "unroll_length": config.unroll_length,
        "fisher": trpo_config.fisher,
        "gae_form": config.gae_form,
        **context(),
    }
    print(
        f"{args.env}, {args.cells} cells, {describe(settings)}; fisher {trpo_config.fisher}, "
        f"update GAE {config.gae_form}; {args.demo_rows} demo rows; device {common['device']}, "
        f"jax {jax.__version__}",
        flush=True,
    )
    timer = compile_phases(
        Phases(trpo, args.demo_rows), evaluation_trpo, args.cells, jax.random.key(args.seed)
    )
    rows = make_rows(timer.time_all(args.rounds), common)
    print("\n" + rows_table(rows) + "\n")
    print(summary(rows, settings.eval_every), flush=True)
    write_rows(args.json, rows)


if __name__ == "__main__":
    main()
