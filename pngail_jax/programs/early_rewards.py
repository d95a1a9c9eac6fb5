"""Where each method's reward points early in training, on the authors' Pendulum-v1 set.

PN-GAIL's curves stay near the random policy for the first ~0.8 M steps of the main job while
GAIL and 2IWIL rise from ~0.2 M. This program trains GAIL, PN-GAIL\\PN (2IWIL's loss with BSC
confidences: PN-GAIL without the negative term), PN-GAIL, and PN-GAIL with 99% of the rows
labelled (nearly the true confidences: is the classifier to blame?) side by side in one
program, and every ``--every`` iterations prints, per method (mean over seeds):

- the evaluation return;
- the policy reward ``sp(-z)`` the discriminator gives the optimal demonstration rows (r = 1),
  the intermediate ones (r < 1), and the agent's own batch.

    python -m experiments.early_rewards --demos data/released/Pendulum-v1_mixture.npy

writes ``early_rewards.json`` (``--out``) and prints a markdown table.
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax.adversarial import AdversarialTrainer
from pngail_jax.confidence import ClassifierConfig
from pngail_jax.demos import load_demonstrations
from pngail_jax.grid import Cell, Grid, stack_cells
from pngail_jax.losses import policy_reward
from pngail_jax.programs.cli import ArgumentParser, HelpFormatter, path_argument
from pngail_jax.run_config import RunConfig
from pngail_jax.settings import make_env

VARIANTS = (  # (label, method, label ratio)
    ("gail", "gail", 0.2),
    ("pngail-no-pn", "pngail-no-pn", 0.2),
    ("pngail", "pngail", 0.2),
    ("pngail, 99% labelled", "pngail", 0.99),
)


def parse_args(argv=None):
    parser = ArgumentParser("early_rewards", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument(
        "--demos", type=path_argument, required=True, help="Pendulum-v1_mixture.npy"
    )
    parser.add_argument("--seeds", type=int, default=3, help="seeds per variant")
    parser.add_argument("--iterations", type=int, default=150, help="TRPO iterations")
    parser.add_argument("--every", type=int, default=10, help="iterations between readings")
    parser.add_argument(
        "--classifier-steps", type=int, default=25_000, help="confidence classifier steps"
    )
    parser.add_argument(
        "--out", type=path_argument, default=Path("early_rewards.json"), help="JSON file"
    )
    args = parser.parse_args(argv)
    if args.seeds < 1 or args.every < 1 or args.iterations < args.every:
        parser.error("need --seeds >= 1 and --iterations >= --every >= 1")
    if args.classifier_steps < 1:
        parser.error("--classifier-steps must be positive")
    if args.out.exists():
        parser.error(f"{args.out} exists: choose another --out")
    return args


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


def main(argv=None) -> dict:
    args = parse_args(argv)
    demos = load_demonstrations(args.demos)  # the authors' file: its known scale, x 2
    table = RunConfig().settings  # Pendulum-v1's row of the settings table
    run = RunConfig(
        iterations=args.iterations,
        label_ratios=(0.2, 0.99),
        settings=dataclasses.replace(table, eval_every=args.every),
        classifier=ClassifierConfig(num_steps=args.classifier_steps),
    )
    env = make_env(run.env, run.settings)
    trainer = AdversarialTrainer(run.adversarial_config(demos.num_rows), env, demos)
    cells = [
        Cell(method, seed, ratio) for _, method, ratio in VARIANTS for seed in range(args.seeds)
    ]
    grid = Grid(trainer, stack_cells(cells, jax.random.key(0)), blocks_per_chunk=1)
    optimal = jnp.asarray(demos.confidence >= 1.0)
    seconds = grid.compile_seconds
    print(f"{len(cells)} runs x {args.iterations} iterations; compiled in {seconds:.0f} s")
    state, _ = grid.init()
    readings = []
    start = time.perf_counter()
    for chunk in range(args.iterations // args.every):
        state, metrics = grid.run_chunk(state)
        on_optimal, on_other = (np.asarray(x) for x in rewards_on_rows(trainer, state, optimal))
        agent = np.asarray(metrics["train/reward"]).mean(axis=1)
        returns = np.asarray(metrics["eval/return"])[:, -1]
        iteration = (chunk + 1) * args.every
        for index, (label, _, _) in enumerate(VARIANTS):
            rows = slice(index * args.seeds, (index + 1) * args.seeds)
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
        print(f"iteration {iteration} ({time.perf_counter() - start:.0f} s)", flush=True)
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
    result = {"seeds": args.seeds, "iterations": args.iterations, "readings": readings}
    args.out.write_text(json.dumps(result, indent=1))
    print(f"-> {args.out}")
    return result
