"""Generate imperfect demonstrations: an optimal and an intermediate TRPO policy, mixed.

    python -m experiments.make_demos --env Pendulum-v1 --out demos/pendulum

1. Trains TRPO on the true reward (``--seeds`` in one program), keeping every evaluated
   checkpoint (``checkpoints/iter_XXXX/``, loadable with ``pngail_jax.load_policy``).
2. The optimal policy is the best-evaluated checkpoint; the intermediate policy is the earlier
   checkpoint whose evaluated normalised return is closest to ``--intermediate-target`` (0.45:
   the authors' Pendulum set has intermediate confidences of 0.37-0.50), not the optimal
   policy plus noise.
3. Measures the random (uniform actions) and optimal returns on fresh episodes (Table 3).
4. Rolls out ``--num-trajectories`` deterministic (mean-action) episodes at the
   optimal:intermediate ``--ratio`` (1:4 as the paper's Pendulum set), labels each trajectory
   with its return normalised between random and optimal (clipped to [0, 1]) and saves
   ``demos.npz`` (our schema; actions clipped to the bounds, as the environment applies them)
   with the normaliser in its metadata.

``demos.npz`` is written last and atomically (a temporary sibling renamed onto it), so its
presence means the run finished; a second run into the same ``--out`` refuses to replace it
unless ``--overwrite`` is given (``experiments.sweep`` only calls this for a missing cache).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from experiments.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    check_env,
    check_finite,
    check_positive,
    claim_output,
    path_argument,
    prepare_output,
)
from experiments.train_rl import train_with_progress
from pngail_jax import compilation
from pngail_jax import settings as run_settings
from pngail_jax.checkpoint import save_trpo_policies
from pngail_jax.demos import Demonstrations, save_npz
from pngail_jax.demos.generate import normalized_return, random_policy_return, rollout_episodes
from pngail_jax.integrity import atomic_path, atomic_write_text
from pngail_jax.rl import TRPOHyperparams, TRPOTrainer

DEMOS_FILE = "demos.npz"  # written last: its presence marks a finished run


class Checkpoint(NamedTuple):
    iteration: int
    seed: int
    policy_params: Any
    normalizer: Any
    eval_return: float


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "make_demos", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("--env", default="Pendulum-v1", help=ENV_HELP)
    parser.add_argument(
        "--out", type=path_argument, required=True, help="output directory (required)"
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an earlier run's demos.npz, normalizer.json and checkpoints in --out "
        "(default: refuse)",
    )
    parser.add_argument("--iterations", type=int, default=150, help="TRPO iterations")
    parser.add_argument("--seeds", type=int, default=3, help="TRPO seeds; the best is optimal")
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument("--ratio", default="1:4", help="optimal:intermediate trajectories")
    parser.add_argument(
        "--num-trajectories", type=int, default=5, help="trajectories in the mixture"
    )
    parser.add_argument(
        "--intermediate-target",
        type=float,
        default=0.45,
        help="normalised return the intermediate policy is picked near",
    )
    parser.add_argument(
        "--measure-episodes",
        type=int,
        default=64,
        help="episodes for the random and optimal returns",
    )
    run_settings.add_arguments(parser)
    # Checkpoints are kept at every evaluation, and the intermediate policy is picked among
    # them: finer than the table's evaluation interval by default.
    parser.set_defaults(eval_every=10)
    compilation.add_arguments(parser)
    args = parser.parse_args(argv)
    claim_output(parser, args.out, "make_demos", args.overwrite)
    check_env(parser, args.env)
    check_positive(parser, args, ("iterations", "seeds", "num_trajectories", "measure_episodes"))
    check_finite(parser, args, ("intermediate_target",))
    try:
        args.settings = run_settings.from_arguments(args.env, args)
    except ValueError as error:
        parser.error(str(error))
    try:
        optimal_part, intermediate_part = (float(x) for x in args.ratio.split(":"))
    except ValueError:
        parser.error(f"--ratio must look like 1:4, got {args.ratio!r}")
    total = optimal_part + intermediate_part
    if not (optimal_part >= 0 and intermediate_part >= 0 and 0 < total < math.inf):  # no NaN
        parser.error(
            f"--ratio parts must be finite, non-negative and not both 0, got {args.ratio!r}"
        )
    args.num_optimal = round(args.num_trajectories * optimal_part / total)
    if args.iterations % args.settings.eval_every:
        parser.error("--iterations must be a multiple of --eval-every")
    try:
        args.settings.trpo_config(args.iterations)
    except ValueError as error:
        parser.error(str(error))
    if not 0 < args.intermediate_target < 1:
        parser.error(f"--intermediate-target must be in (0, 1), got {args.intermediate_target}")
    return args


def write_outputs(out: Path, demos: Demonstrations, normalizer: dict) -> Path:
    """``normalizer.json``, then ``demos.npz`` (the mark of a finished run), each written to
    a temporary sibling and renamed, so a kill never leaves a truncated file behind."""
    atomic_write_text(out / "normalizer.json", json.dumps(normalizer, indent=2))
    path = out / DEMOS_FILE
    with atomic_path(path) as temporary:  # keeps the .npz suffix np.savez would append
        save_npz(temporary, demos)
    return path


def main(argv=None) -> Path:
    args = parse_args(argv)
    compilation.from_arguments(args)
    try:
        env = run_settings.make_env(args.env, args.settings)
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise SystemExit(f"environment: {error}") from None
    prepare_output(args.out, "make_demos", args.overwrite)  # an old run kept until here
    config = args.settings.trpo_config(args.iterations)
    trainer = TRPOTrainer(config, env)
    policy = trainer.trpo.policy
    hyperparams = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (args.seeds, *x.shape)), TRPOHyperparams.create()
    )
    train_key, measure_key, demo_key = jax.random.split(jax.random.key(args.seed), 3)
    snapshots: list[Checkpoint] = []

    def keep(iteration, state, metrics):
        returns = metrics["eval/return"][:, -1]
        save_trpo_policies(
            args.out / "checkpoints" / f"iter_{iteration:04d}", env, config, state, returns
        )
        for seed in range(args.seeds):
            pick = jax.tree.map(lambda x, s=seed: x[s], (state.policy_params, state.normalizer))
            snapshots.append(Checkpoint(iteration, seed, *pick, float(returns[seed])))

    start = time.perf_counter()
    print(
        f"1/3 training TRPO on {args.env} ({args.seeds} seeds x {args.iterations} iterations; "
        f"{run_settings.describe(args.settings)})",
        flush=True,
    )
    train_with_progress(
        trainer, hyperparams, jax.random.split(train_key, args.seeds), on_block=keep
    )

    @jax.jit  # one program for every policy (its parameters are arguments, not constants)
    def policy_episodes(params, normalizer, keys):
        def act(obs, key):
            return policy.apply(params, normalizer(obs))[0]

        return rollout_episodes(env, act, keys)

    def measure(snapshot, key, num_episodes):
        keys = jax.random.split(key, num_episodes)
        return policy_episodes(snapshot.policy_params, snapshot.normalizer, keys)

    print("2/3 measuring random and optimal returns", flush=True)
    random_key, optimal_key, intermediate_key = jax.random.split(measure_key, 3)
    random_return = random_policy_return(env, random_key, args.measure_episodes)
    best = max(snapshots, key=lambda snapshot: snapshot.eval_return)
    optimal_return = float(measure(best, optimal_key, args.measure_episodes).returns.mean())
    beats_random = optimal_return > random_return
    if not beats_random:
        print(
            f"WARNING: the best policy ({optimal_return:.1f}) does not beat the random one "
            f"({random_return:.1f}); confidences will be meaningless. Train longer "
            "(--iterations).",
            flush=True,
        )
    # An earlier checkpoint; if the best came first, any other one (and say so).
    candidates = [s for s in snapshots if s.iteration < best.iteration]
    if not candidates:
        print(
            "WARNING: the best checkpoint is the first one; the intermediate policy is "
            "picked among the later ones",
            flush=True,
        )
        candidates = [s for s in snapshots if s is not best] or snapshots
    intermediate = min(
        candidates,
        key=lambda s: abs(
            normalized_return(s.eval_return, random_return, optimal_return)
            - args.intermediate_target
        ),
    )
    intermediate_return = float(
        measure(intermediate, intermediate_key, args.measure_episodes).returns.mean()
    )

    print(
        f"3/3 rolling out {args.num_optimal} optimal + "
        f"{args.num_trajectories - args.num_optimal} intermediate trajectories",
        flush=True,
    )
    optimal_key, intermediate_key = jax.random.split(demo_key)
    sources = [
        (best, optimal_key, args.num_optimal),
        (intermediate, intermediate_key, args.num_trajectories - args.num_optimal),
    ]
    parts = [measure(snapshot, key, count) for snapshot, key, count in sources if count > 0]
    rows = {"observations": [], "actions": [], "confidence": [], "trajectory_ids": []}
    trajectory_returns = []
    for episodes in parts:
        episodes = jax.device_get(episodes)
        for index in range(len(episodes.returns)):
            valid = episodes.valid[index]
            confidence = float(
                np.clip(
                    normalized_return(episodes.returns[index], random_return, optimal_return),
                    0.0,
                    1.0,
                )
            )
            trajectory_returns.append(float(episodes.returns[index]))
            rows["observations"].append(episodes.observations[index][valid])
            rows["actions"].append(
                np.clip(episodes.actions[index][valid], env.action_low, env.action_high)
            )
            rows["confidence"].append(np.full(valid.sum(), confidence, np.float32))
            rows["trajectory_ids"].append(np.full(valid.sum(), len(trajectory_returns) - 1))
    metadata = {
        "env": args.env,
        "action_scale": 1.0,
        "random_return": random_return,
        "optimal_return": optimal_return,
        "intermediate_return": intermediate_return,
        "optimal_checkpoint": {"iteration": best.iteration, "seed": best.seed},
        "intermediate_checkpoint": {"iteration": intermediate.iteration, "seed": intermediate.seed},
        "ratio": args.ratio,
        # The optimal policy's trajectories come first (ids 0 .. num_optimal - 1).
        "num_optimal_trajectories": args.num_optimal,
        "trajectory_returns": trajectory_returns,
        "optimal_beats_random": beats_random,
        "source": "experiments.make_demos (deterministic TRPO policies)",
        "env_options": args.settings.env_options,
    }
    demos = Demonstrations(**{k: np.concatenate(v) for k, v in rows.items()}, metadata=metadata)
    demos.check_env(env)
    path = write_outputs(
        args.out, demos, {k: metadata[k] for k in ("env", "random_return", "optimal_return")}
    )
    print(
        f"\n| policy | return | normalised |\n|---|---:|---:|\n"
        f"| random (uniform actions) | {random_return:.1f} | 0.00 |\n"
        f"| optimal (iter {best.iteration}, seed {best.seed}) | {optimal_return:.1f} | 1.00 |\n"
        f"| intermediate (iter {intermediate.iteration}, seed {intermediate.seed}) | "
        f"{intermediate_return:.1f} | "
        f"{normalized_return(intermediate_return, random_return, optimal_return):.2f} |"
    )
    confidences = [float(c[0]) for c in rows["confidence"]]
    print(
        f"\n{demos.num_rows} rows in {len(confidences)} trajectories, confidences "
        f"{[round(c, 2) for c in confidences]}; wrote {path} "
        f"in {time.perf_counter() - start:.0f} s"
    )
    return path


if __name__ == "__main__":
    main()
