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
import json
import shutil
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from pngail_jax import runner
from pngail_jax import settings as run_settings
from pngail_jax.checkpoint import save_trpo_policies
from pngail_jax.integrity import (
    IntegrityError,
    atomic_path,
    read_json,
    write_json,
    write_manifest,
)
from pngail_jax.outputs import RunLocked, run_lock
from pngail_jax.programs import flags
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    add_compile_cache_flags,
    check_env,
    check_positive,
    claim_output,
    note_deprecated,
    output_owner,
    path_argument,
    prepare_output,
    signals_stop_at_a_checkpoint,
    use_compile_cache,
)
from pngail_jax.rl import TRPOHyperparams, TRPOTrainer
from pngail_jax.runner import RunError

METRIC_COLUMNS = (
    "env_steps",
    "eval/return",
    "train/episode_return",
    "trpo/kl",
    "trpo/entropy",
    "trpo/accepted",
    "value/loss",
)


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(
        "train_rl", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    add = parser.add_argument
    add("--env", default="Pendulum-v1", help=ENV_HELP)
    add("--iterations", type=int, default=100, help="TRPO iterations")
    add("--seeds", type=int, default=3, help="seeds, trained side by side")
    add("--seed", type=int, default=0, help="base PRNG seed")
    add(
        "--out",
        type=path_argument,
        default=None,
        help="output directory (default runs/trpo-<env>-<timestamp>)",
    )
    add(
        "--overwrite",
        action="store_true",
        help="replace a trained policy already in --out (default: refuse)",
    )
    add(
        "--resume",
        type=path_argument,
        metavar="DIR",
        help="continue DIR's interrupted run from its last checkpoint, with its own flags "
        "(default: a new run)",
    )
    add(
        "--fisher",
        choices=("hessian", "gauss_newton"),
        default="gauss_newton",
        help="Fisher-vector product form (the same matrix; hessian is the reference's form)",
    )
    add("--fisher-subsample", type=int, default=1, help="Fisher products on every k-th step")
    add(
        "--truncation-as-terminal",
        action="store_true",
        help="the reference's GAE: no bootstrapping through time limits",
    )
    add("--fast-solver", action="store_true", help="deprecated: the same as --solver fast")
    flags.add_settings_flags(parser)
    add_compile_cache_flags(parser)
    return parser


# What --resume DIR takes besides itself: the run's config.json holds every other flag.
RESUME_FLAGS = ("--resume", "--compile-cache", "--no-compile-cache")


def parse_args(argv=None) -> argparse.Namespace:
    """The checked flags of ``argv``: of a new run (its ``--out`` claimed), or of the run that
    ``--resume DIR`` continues (its own flags, read from its config.json)."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    if args.resume is not None:
        return _resumed_args(parser, args, argv)
    note_deprecated(argv, {"--fast-solver": "--solver fast"})
    _check(parser, args)
    if args.out is None:
        args.out = Path("runs") / f"trpo-{args.env}-{time.strftime('%Y%m%d-%H%M%S')}"
    claim_output(parser, args.out, "train_rl", args.overwrite)
    args.argv = argv
    return args


def _check(parser, args) -> None:
    check_env(parser, args.env)
    if args.fast_solver:
        if args.solver not in (None, "fast"):
            parser.error("--fast-solver and --solver disagree")
        args.solver = "fast"
    check_positive(parser, args, ("iterations", "seeds", "fisher_subsample"))
    args.settings = flags.settings_from_flags(parser, args, args.env)
    if args.iterations % args.settings.eval_every:
        parser.error(
            f"--iterations ({args.iterations}) must be a multiple of the evaluation interval "
            f"({args.settings.eval_every}, --eval-every)"
        )
    try:
        args.settings.trpo_config(args.iterations)
    except ValueError as error:
        parser.error(str(error))


def _resumed_args(parser, given: argparse.Namespace, argv: list[str]) -> argparse.Namespace:
    """The flags of the run in ``--resume DIR`` (its config.json's ``argv``), checked again,
    with the compilation-cache flags of this command."""
    directory = given.resume
    if any(a.split("=")[0] not in RESUME_FLAGS for a in argv if a.startswith("--")):
        parser.error("--resume DIR takes no other flags: the run's config.json has them")
    if output_owner(directory) != "train_rl":
        parser.error(f"--resume {directory} holds no run of experiments.train_rl")
    if (directory / "policy.json").exists():
        parser.error(f"--resume {directory}: the run is complete (its policy.json is written)")
    try:
        stored = read_json(directory / "config.json", "train_rl run config")["argv"]
    except (OSError, IntegrityError, KeyError, TypeError) as error:
        parser.error(f"--resume {directory}: no flags to resume with ({error})")
    args = parser.parse_args(stored)
    _check(parser, args)
    args.out, args.resume, args.argv = directory, directory, stored
    args.compile_cache, args.no_compile_cache = given.compile_cache, given.no_compile_cache
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
    use_compile_cache(args)
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
    run_config = {
        "env": args.env,
        "env_options": settings.env_options,
        "settings": dataclasses.asdict(settings),
        "seeds": args.seeds,
        "seed": args.seed,
        "trpo": dataclasses.asdict(config),
        "hyperparams": jax.tree.map(lambda x: x.item(), hyperparams).__dict__,
        "argv": args.argv,
    }
    try:
        with signals_stop_at_a_checkpoint(), run_lock(args.out, "train_rl"):
            _train(args, env, trainer, seeds_hyperparams, keys, run_config)
    except (RunLocked, RunError) as error:
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        raise SystemExit(
            f"\ninterrupted: finished blocks are kept; --resume {args.out} continues from the "
            "last one"
        ) from None


def _train(args, env, trainer, seeds_hyperparams, keys, run_config) -> None:
    config, settings = trainer.config, args.settings
    if args.resume is None:
        prepare_output(args.out, "train_rl", args.overwrite)
        write_json(args.out / "config.json", run_config)
    else:  # checked again under the lock: another resume may have finished it meanwhile
        if (args.out / "policy.json").exists():
            raise RunError(f"--resume {args.out}: the run is complete (its policy.json is written)")
        stored = read_json(args.out / "config.json", "train_rl run config")
        if json.loads(json.dumps(run_config)) != stored:  # another version's defaults
            raise RunError(
                f"cannot resume {args.out}: its flags give another run in this version "
                "(config.json differs); start a new run"
            )
    print(
        f"TRPO on {args.env}: {args.seeds} seeds x {args.iterations} iterations x "
        f"{config.batch_size} steps ({run_settings.describe(settings)}) -> {args.out}",
        flush=True,
    )
    start = time.perf_counter()
    state, metrics = runner.train_seeds(
        trainer, seeds_hyperparams, keys, checkpoints=args.out / "checkpoints"
    )
    final_returns = metrics["eval/return"][:, -1]
    write_metrics_csv(args.out / "metrics.csv", metrics)
    plot_learning_curve(
        args.out / "learning_curve.png", metrics, f"TRPO on {args.env} ({args.seeds} seeds)"
    )
    save_trpo_policies(
        args.out, env, config, state, final_returns, {"env_options": settings.env_options}
    )
    # The run is complete: its checkpoints go, and the digests list what stays.
    shutil.rmtree(args.out / "checkpoints", ignore_errors=True)
    write_manifest(args.out)
    print(
        f"done in {time.perf_counter() - start:.0f} s; final deterministic returns "
        f"[{', '.join(f'{r:.1f}' for r in final_returns)}] (mean {final_returns.mean():.1f}); "
        f"wrote {args.out}/{{config.json,metrics.csv,learning_curve.png,policy.json}}"
    )


if __name__ == "__main__":
    main()
