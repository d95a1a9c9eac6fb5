"""``early_rewards(config, json_path)``: where each method's reward points early in training.

PN-GAIL's curves stay near the random policy for the first ~0.8 M steps of the Pendulum-v1
job while GAIL and 2IWIL rise from ~0.2 M. This job trains GAIL, PN-GAIL\\PN (2IWIL's loss
with BSC confidences: PN-GAIL without the negative term), PN-GAIL, and PN-GAIL with 99% of
the rows labelled (nearly the true confidences: is the classifier to blame?) side by side in
one program, and every ``every`` iterations (one chunk, by the jobs' one chunk step) reads,
per variant (mean over seeds):

- the evaluation return;
- the policy reward ``sp(-z)`` the discriminator gives the optimal demonstration rows (r = 1),
  the intermediate ones (r < 1), and the agent's own batch.

    from pngail_jax.jobs.early_rewards import EarlyRewardsConfig, early_rewards

    early_rewards(EarlyRewardsConfig("data/released/Pendulum-v1_mixture.npy"), "early.json")
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax.adversarial.family import ADVERSARIAL
from pngail_jax.adversarial.losses import policy_reward
from pngail_jax.adversarial.trainer import AdversarialTrainer
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.config.run_config import RunConfig
from pngail_jax.config.settings import make_env
from pngail_jax.demos import DemonstrationError, load_demonstrations
from pngail_jax.grid import Cell, Grid, stack_cells
from pngail_jax.jobs import trainer_configs
from pngail_jax.jobs.chunks import run_chunks, start
from pngail_jax.jobs.errors import RunError

VARIANTS = (  # (label, method, label ratio)
    ("gail", "gail", 0.2),
    ("pngail-no-pn", "pngail-no-pn", 0.2),
    ("pngail", "pngail", 0.2),
    ("pngail, 99% labelled", "pngail", 0.99),
)


@dataclasses.dataclass(frozen=True)
class EarlyRewardsConfig:
    """The authors' Pendulum-v1 file (``demos``), seeds per variant, TRPO iterations, the
    iterations between readings (``every``) and the confidence classifier's steps."""

    demos: str
    seeds: int = 3
    iterations: int = 150
    every: int = 10
    classifier_steps: int = 25_000

    def __post_init__(self):
        if not (self.seeds >= 1 and self.iterations >= self.every >= 1):
            raise ValueError("need seeds >= 1 and iterations >= every >= 1")
        if self.iterations % self.every:
            raise ValueError(
                f"iterations ({self.iterations}) must be a multiple of every ({self.every}): "
                "a reading ends each block of every iterations"
            )
        if self.classifier_steps < 1:
            raise ValueError("classifier_steps must be positive")


def early_rewards(config: EarlyRewardsConfig, json_path=None) -> dict:
    """Runs the four variants, prints each reading's line and the table, writes the readings
    to ``json_path`` when given (never over an existing file) and returns them. Raises
    ``RunError`` with one line."""
    if json_path is not None and Path(json_path).exists():
        raise RunError(f"{json_path} exists: choose another output file")
    try:
        demos = load_demonstrations(config.demos)  # the authors' file: its known scale, x 2
    except (DemonstrationError, FileNotFoundError) as error:
        raise RunError(f"demonstrations: {error}") from None
    trainer, grid = _build(config, demos)
    optimal = jnp.asarray(demos.confidence >= 1.0)
    num_cells = len(VARIANTS) * config.seeds
    print(
        f"{num_cells} runs x {config.iterations} iterations; compiled in "
        f"{grid.compile_seconds:.0f} s"
    )
    readings = _read_every_chunk(config, trainer, grid, optimal)
    _print_table(readings)
    result = {"seeds": config.seeds, "iterations": config.iterations, "readings": readings}
    if json_path is not None:
        Path(json_path).write_text(json.dumps(result, indent=1))
        print(f"-> {json_path}")
    return result


def _build(config: EarlyRewardsConfig, demos) -> tuple[AdversarialTrainer, Grid]:
    """The trainer of Pendulum-v1's settings (evaluated every ``every`` iterations) and the
    grid of every variant x seed, one evaluation block per chunk."""
    table = RunConfig().settings  # Pendulum-v1's row of the settings table
    run = RunConfig(
        iterations=config.iterations,
        label_ratios=(0.2, 0.99),
        settings=dataclasses.replace(table, eval_every=config.every),
        classifier=ClassifierConfig(num_steps=config.classifier_steps),
    )
    env = make_env(run.env, run.settings)
    try:
        trainer = AdversarialTrainer(
            trainer_configs.adversarial_config(run, demos.num_rows), env, demos
        )
    except (DemonstrationError, ValueError) as error:
        raise RunError(f"{config.demos}: {error}") from None
    cells = [
        Cell(method, seed, ratio) for _, method, ratio in VARIANTS for seed in range(config.seeds)
    ]
    return trainer, Grid(
        trainer, stack_cells(cells, jax.random.key(0), family=ADVERSARIAL), blocks_per_chunk=1
    )


def _read_every_chunk(config: EarlyRewardsConfig, trainer, grid: Grid, optimal) -> list[dict]:
    """One reading per variant after each chunk (``every`` iterations)."""
    readings = []
    began = time.perf_counter()

    def read(state, _host_state, metrics):
        on_optimal, on_other = (np.asarray(x) for x in rewards_on_rows(trainer, state, optimal))
        agent = np.asarray(metrics["train/reward"]).mean(axis=1)
        returns = np.asarray(metrics["eval/return"])[:, -1]
        iteration = (len(readings) // len(VARIANTS) + 1) * config.every
        for index, (label, _, _) in enumerate(VARIANTS):
            rows = slice(index * config.seeds, (index + 1) * config.seeds)
            readings.append(
                {
                    "iteration": iteration,
                    "variant": label,
                    "eval_return": float(returns[rows].mean()),
                    "reward_optimal_rows": float(on_optimal[rows].mean()),
                    "reward_intermediate_rows": float(on_other[rows].mean()),
                    "reward_agent": float(agent[rows].mean()),
                }
            )

    def line(progress, _metrics) -> str:
        iteration = progress.chunks_done * config.every
        return f"iteration {iteration} ({time.perf_counter() - began:.0f} s)"

    state, progress = start(grid, None)
    steps_per_chunk = grid.num_cells * trainer.config.rollout.batch_size * config.every
    run_chunks(
        grid, state, progress, config.iterations // config.every,
        steps_per_chunk=steps_per_chunk, line=line, after=read,
    )  # fmt: skip
    return readings


def rewards_on_rows(trainer: AdversarialTrainer, state, optimal: jax.Array):
    """Mean policy reward sp(-z) of each cell's discriminator on the optimal (bool[N]) and
    the other demonstration rows: float[C] each."""
    inputs = trainer.demo_inputs

    def one(params):
        reward = policy_reward(trainer.discriminator.apply(params, inputs))
        return (
            jnp.sum(jnp.where(optimal, reward, 0)) / optimal.sum(),
            jnp.sum(jnp.where(optimal, 0, reward)) / (~optimal).sum(),
        )

    return jax.jit(jax.vmap(one))(state.discriminator_params)


def _print_table(readings: list[dict]) -> None:
    print(
        "\n| iteration | variant | eval return | reward: optimal rows | intermediate rows | "
        "agent |\n|---:|---|---:|---:|---:|---:|"
    )
    for r in readings:
        print(
            f"| {r['iteration']} | {r['variant']} | {r['eval_return']:.0f} | "
            f"{r['reward_optimal_rows']:.3f} | {r['reward_intermediate_rows']:.3f} | "
            f"{r['reward_agent']:.3f} |"
        )
