"""Train TRPO on an environment's true reward, several seeds in one compiled program.

    python -m experiments.train_rl --env Pendulum-v1 --iterations 100 --seeds 3 --out runs/trpo

Shows progress every ``--eval-every`` iterations (iteration, evaluation and training returns,
steps/s), then writes to ``--out``: ``config.json``, ``metrics.csv`` (one row per seed and
iteration), ``learning_curve.png`` and the policies (``policy.json`` + ``policy_params/``),
which ``pngail_jax.load_policy(out)`` loads without this code.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax import compilation, runner
from pngail_jax import settings as run_settings
from pngail_jax.checkpoint import save_trpo_policies
from pngail_jax.integrity import atomic_path, write_json
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    check_env,
    check_positive,
    claim_output,
    note_deprecated,
    path_argument,
    prepare_output,
)
from pngail_jax.rl import TRPOHyperparams, TRPOTrainer

METRIC_COLUMNS = (
    "env_steps",
    "eval/return",
    "train/episode_return",
    "trpo/kl",
    "trpo/entropy",
    "trpo/accepted",
    "value/loss",
)


def parse_args(argv=None) -> argparse.Namespace:
    parser = ArgumentParser(
        "train_rl", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument("--env", default="Pendulum-v1", help=ENV_HELP)
    parser.add_argument("--iterations", type=int, default=100, help="TRPO iterations")
    parser.add_argument("--seeds", type=int, default=3, help="seeds, trained side by side")
    parser.add_argument("--seed", type=int, default=0, help="base PRNG seed")
    parser.add_argument(
        "--out",
        type=path_argument,
        default=None,
        help="output directory (default runs/trpo-<env>-<timestamp>)",
    )
    parser.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a trained policy already in --out (default: refuse)",
    )
    parser.add_argument(
        "--fisher",
        choices=("hessian", "gauss_newton"),
        default="gauss_newton",
        help="Fisher-vector product form (the same matrix; hessian is the reference's form)",
    )
    parser.add_argument(
        "--fisher-subsample", type=int, default=1, help="Fisher products on every k-th step"
    )
    parser.add_argument(
        "--truncation-as-terminal",
        action="store_true",
        help="the reference's GAE: no bootstrapping through time limits",
    )
    parser.add_argument(
        "--fast-solver", action="store_true", help="deprecated: the same as --solver fast"
    )
    run_settings.add_arguments(parser)
    compilation.add_arguments(parser)
    args = parser.parse_args(argv)
    note_deprecated(argv, {"--fast-solver": "--solver fast"})
    check_env(parser, args.env)
    if args.fast_solver:
        if args.solver not in (None, "fast"):
            parser.error("--fast-solver and --solver disagree")
        args.solver = "fast"
    check_positive(parser, args, ("iterations", "seeds", "fisher_subsample"))
    try:
        args.settings = run_settings.from_arguments(args.env, args)
    except ValueError as error:
        parser.error(str(error))
    if args.iterations % args.settings.eval_every:
        parser.error(
            f"--iterations ({args.iterations}) must be a multiple of the evaluation interval "
            f"({args.settings.eval_every}; set it with --eval-every)"
        )
    try:
        args.settings.trpo_config(args.iterations)
    except ValueError as error:
        parser.error(str(error))
    if args.out is None:
        args.out = Path("runs") / f"trpo-{args.env}-{time.strftime('%Y%m%d-%H%M%S')}"
    claim_output(parser, args.out, "train_rl", args.overwrite)
    return args


def write_metrics_csv(path: Path, metrics: dict[str, np.ndarray]) -> None:
    num_seeds, num_iterations = metrics["env_steps"].shape
    with atomic_path(path) as temporary, temporary.open("w", newline="") as file:
        writer = csv.writer(file)
        writer.writerow(["seed", "iteration", *METRIC_COLUMNS])
        for seed in range(num_seeds):
            for iteration in range(num_iterations):
                values = [metrics[name][seed, iteration] for name in METRIC_COLUMNS]
                writer.writerow([seed, iteration + 1, *(f"{v:.6g}" for v in values)])


def plot_learning_curve(path: Path, metrics: dict[str, np.ndarray], title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(7, 4.5))
    steps = metrics["env_steps"][0]
    evaluated = ~np.isnan(metrics["eval/return"][0])
    for seed, returns in enumerate(metrics["eval/return"]):
        axis.plot(
            steps[evaluated],
            returns[evaluated],
            color="tab:blue",
            alpha=0.35,
            lw=1,
            label="seeds (deterministic eval)" if seed == 0 else None,
        )
    mean = metrics["eval/return"][:, evaluated].mean(axis=0)
    axis.plot(steps[evaluated], mean, color="black", lw=2, marker="o", ms=3, label="mean")
    train_mean = runner.nanmean(metrics["train/episode_return"], axis=0)
    # Iterations where no episode ended are NaN (a 1000-step episode ends every fifth
    # 200-step iteration): joined over them, or matplotlib draws isolated, invisible points.
    ended = np.isfinite(train_mean)
    axis.plot(
        steps[ended], train_mean[ended], color="tab:orange", lw=1, label="training episodes (mean)"
    )
    axis.set(xlabel="environment steps", ylabel="episode return", title=title)
    axis.grid(alpha=0.3)
    axis.legend()
    figure.tight_layout()
    with atomic_path(path) as temporary:
        figure.savefig(temporary, dpi=120)
    plt.close(figure)


def main(argv=None) -> None:
    args = parse_args(argv)
    compilation.from_arguments(args)
    settings = args.settings
    try:
        env = run_settings.make_env(args.env, settings)
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise SystemExit(f"environment: {error}") from None
    config = settings.trpo_config(
        args.iterations, fisher=args.fisher, fisher_subsample=args.fisher_subsample
    )
    hyperparams = TRPOHyperparams.create(bootstrap_truncation=not args.truncation_as_terminal)
    trainer = TRPOTrainer(config, env)
    seeds_hyperparams = jax.tree.map(
        lambda x: jnp.broadcast_to(x, (args.seeds, *x.shape)), hyperparams
    )
    keys = jax.random.split(jax.random.key(args.seed), args.seeds)
    prepare_output(args.out, "train_rl", args.overwrite)
    run_config = {
        "env": args.env,
        "env_options": settings.env_options,
        "settings": dataclasses.asdict(settings),
        "seeds": args.seeds,
        "seed": args.seed,
        "trpo": dataclasses.asdict(config),
        "hyperparams": jax.tree.map(lambda x: x.item(), hyperparams).__dict__,
    }
    write_json(args.out / "config.json", run_config)

    print(
        f"TRPO on {args.env}: {args.seeds} seeds x {args.iterations} iterations x "
        f"{config.batch_size} steps ({run_settings.describe(settings)}) -> {args.out}",
        flush=True,
    )
    start = time.perf_counter()
    state, metrics = runner.train_seeds(trainer, seeds_hyperparams, keys)
    final_returns = metrics["eval/return"][:, -1]
    write_metrics_csv(args.out / "metrics.csv", metrics)
    plot_learning_curve(
        args.out / "learning_curve.png", metrics, f"TRPO on {args.env} ({args.seeds} seeds)"
    )
    save_trpo_policies(
        args.out, env, config, state, final_returns, {"env_options": settings.env_options}
    )
    print(
        f"done in {time.perf_counter() - start:.0f} s; final deterministic returns "
        f"[{', '.join(f'{r:.1f}' for r in final_returns)}] (mean {final_returns.mean():.1f}); "
        f"wrote {args.out}/{{config.json,metrics.csv,learning_curve.png,policy.json}}"
    )


if __name__ == "__main__":
    main()
