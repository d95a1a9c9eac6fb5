"""The offline family on a task's demonstrations: BC on the expert rows, BC on every row,
DWBC and ISW-BC, every method x seed in one compiled program.

    python -m experiments.offline --demos data/released/Pendulum-v1_mixture.npy --out runs/offline
    python -m experiments.offline --resume runs/offline    # a run cut short, from its checkpoints

The data they see is PN-GAIL's: each seed's split labels a ``--label-ratio`` share of the rows
(D_c); the expert set is D_c's rows at confidence >= 0.5 (``<method>+bsc``: plus D_u's rows a
BSC classifier puts there). Writes config.json, metrics.csv, summary.json / summary.md (IQM,
intervals, each method's probability of beating BC on every row) and curves.png into --out;
docs/methods.md ("Offline methods") has the losses and their codebases' settings.
"""

from __future__ import annotations

import argparse
import re
import sys

from pngail_jax.config.validation import ConfigError
from pngail_jax.demos import released_task
from pngail_jax.jobs.errors import RunError
from pngail_jax.jobs.offline import OfflineRunConfig, load_offline_config, run_offline
from pngail_jax.jobs.offline_config import EVERY_100TH
from pngail_jax.offline.ilid import ILID_UNIONS
from pngail_jax.offline.trainer import (
    CLASSIFIED_SUFFIX,
    DEFAULT_OFFLINE_METHODS,
    OFFLINE_METHOD_NAMES,
)
from pngail_jax.programs.cli import (
    ENV_HELP,
    ArgumentParser,
    HelpFormatter,
    add_allow_unsealed,
    add_compile_cache_flags,
    check_env,
    claim_output,
    interrupted,
    invoked_as,
    path_argument,
    signals_stop_at_a_checkpoint,
    use_compile_cache,
)
from pngail_jax.storage.outputs import output_owner

DEFAULTS = OfflineRunConfig()
# OfflineRunConfig's fields whose flag is not the field's name with dashes.
FLAGS = {"noise_std": "--noise"}


def flag_of(field: str) -> str:
    """The flag that sets ``OfflineRunConfig``'s ``field``."""
    return FLAGS.get(field, "--" + field.replace("_", "-"))


def flag_words(message: str) -> str:
    """``message`` with the other settings a check names (a block of steps, say) called by
    their flags too."""
    return re.sub(r"\b(gradient_steps|steps_per_iteration|eval_every)\b",
                  lambda match: flag_of(match.group(1)), message)  # fmt: skip


def build_parser() -> ArgumentParser:
    """The program's flags (``parse_args`` checks them)."""
    parser = ArgumentParser(
        "offline", description=__doc__.split("\n\n")[0], formatter_class=HelpFormatter
    )
    parser.add_argument(
        "--env",
        help=f"{ENV_HELP} (default: the task of an authors' --demos file, e.g. Hopper-v4 for "
        f"Hopper-v2_mixture.npy; else {DEFAULTS.env})",
    )
    parser.add_argument("--demos", help="demonstrations (default: made once and cached)")
    parser.add_argument("--conf", help="their confidence file (default: beside an authors' file)")
    parser.add_argument("--action-scale", type=float, help="multiplies the stored actions")
    parser.add_argument(
        "--methods",
        default=",".join(DEFAULT_OFFLINE_METHODS),
        help=f"comma-separated, of {', '.join(OFFLINE_METHOD_NAMES)} (ilid needs trajectories: a "
        "made set or the authors' Pendulum file), each also as "
        f"<name>{CLASSIFIED_SUFFIX}",
    )
    parser.add_argument("--seeds", type=int, default=DEFAULTS.seeds)
    parser.add_argument("--seed", type=int, default=DEFAULTS.seed, help="base PRNG seed")
    parser.add_argument("--label-ratio", type=float, default=DEFAULTS.label_ratio)
    parser.add_argument("--noise", type=float, default=DEFAULTS.noise_std, dest="noise_std",
                        help="confidence noise std")  # fmt: skip
    parser.add_argument(
        "--gradient-steps", type=int, default=DEFAULTS.gradient_steps,
        help="gradient steps per run (DWBC's codebase: 500,000; ISW-BC's: 1,000,000)",
    )  # fmt: skip
    parser.add_argument("--steps-per-iteration", type=int, default=DEFAULTS.steps_per_iteration)
    parser.add_argument(
        "--eval-every", type=int, default=DEFAULTS.eval_every,
        help="iterations (of --steps-per-iteration gradient steps) per evaluation",
    )  # fmt: skip
    parser.add_argument("--chunk-iterations", type=int, default=DEFAULTS.chunk_iterations,
                        help="iterations per compiled chunk (a progress line each)")  # fmt: skip
    parser.add_argument("--batch-size", type=int, default=DEFAULTS.batch_size)
    _add_ilid_flags(parser)
    parser.add_argument("--out", type=path_argument, help="output directory (required)")
    parser.add_argument(
        "--resume", type=path_argument, metavar="DIR",
        help="continue the offline run in DIR from its checkpoints, with the config it began "
        "with (no other flag is read)",
    )  # fmt: skip
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an earlier offline run in --out"
    )
    add_allow_unsealed(parser.add_argument, "--resume a run")
    add_compile_cache_flags(parser)
    return parser


def _dwbc_updates(value: str) -> int | str | None:
    """--dwbc-discriminator-updates' value: a count (checked by the config), or every-100
    (None: the cadence before 5,000 became the default)."""
    if value == EVERY_100TH:
        return None
    try:
        return int(value)
    except ValueError:
        return value  # the config refuses it in one line, naming the flag


def _add_ilid_flags(parser: ArgumentParser) -> None:
    """ILID's flags (its discriminators' budget and the union it draws from) and DWBC's
    discriminator budget."""
    parser.add_argument(
        "--dwbc-discriminator-updates", type=_dwbc_updates,
        default=DEFAULTS.dwbc_discriminator_updates,
        help="Adam steps of DWBC's discriminator over the run, evenly spaced (must divide "
        "--gradient-steps, or be at least it: one a step); default: its codebase's 5,000 "
        f"(of its 500,000 steps; every 10th of 50,000); {EVERY_100TH}: one every 100th step, "
        "as runs did before 5,000 became the default",
    )  # fmt: skip
    parser.add_argument(
        "--ilid-discriminator-steps", type=int, default=DEFAULTS.ilid_discriminator_steps,
        help="Adam steps of each of ILID's two discriminators, before its policy learns "
        "(default: its codebase's 100,000, 90 minutes for a 5-seed grid on 2 CPU cores beside "
        "other jobs; 5,000 with --ilid-discriminator-learning-rate 2e-4 took about 5 and did "
        "no worse on Pendulum and Ant, docs/results/offline.md)",
    )  # fmt: skip
    parser.add_argument(
        "--ilid-discriminator-learning-rate", type=float,
        default=DEFAULTS.ilid_discriminator_learning_rate,
        help="their Adam step size (its codebase's: 1e-5; with 20 times fewer steps, 2e-4 "
        "covers the same distance)",
    )  # fmt: skip
    parser.add_argument(
        "--ilid-union", choices=ILID_UNIONS, default=DEFAULTS.ilid_union,
        help="the union ILID's state-action discriminator and weighted BC draw from: intended "
        "(the expert and selected rows) or released (as its released code samples it: each "
        "draw a zero row with probability 1e6 / (1e6 + |E| + |S|), its buffer's 1,000,000 zero "
        "rows in front; docs/methods.md)",
    )  # fmt: skip


def parse_args(argv=None) -> argparse.Namespace:
    """The checked flags of ``argv``: a resumed run's folder, or a new run's config."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    args.argv = argv
    if args.resume is not None:
        if args.out is not None and args.out != args.resume:
            parser.error("--resume DIR continues the run in DIR: drop --out")
        owner = output_owner(args.resume)
        if owner != "offline":
            held = f"it holds a run of experiments.{owner}" if owner else "no offline run there"
            parser.error(f"--resume {args.resume}: {held}")
        args.out = args.resume
        return args
    if args.allow_unsealed:
        parser.error("--allow-unsealed is for --resume DIR (a new run writes its own seal)")
    if args.out is None:
        parser.error("--out is required (or --resume DIR)")
    claim_output(parser, args.out, "offline", args.overwrite)
    task = released_task(args.demos) if args.demos else None
    args.env = check_env(parser, args.env or task or DEFAULTS.env)
    try:
        args.config = OfflineRunConfig(
            env=args.env, demos=args.demos, conf=args.conf, action_scale=args.action_scale,
            methods=tuple(name.strip() for name in args.methods.split(",") if name.strip()),
            seeds=args.seeds, seed=args.seed, label_ratio=args.label_ratio,
            noise_std=args.noise_std, gradient_steps=args.gradient_steps,
            steps_per_iteration=args.steps_per_iteration, eval_every=args.eval_every,
            chunk_iterations=args.chunk_iterations, batch_size=args.batch_size,
            ilid_discriminator_steps=args.ilid_discriminator_steps,
            ilid_discriminator_learning_rate=args.ilid_discriminator_learning_rate,
            ilid_union=args.ilid_union,
            dwbc_discriminator_updates=args.dwbc_discriminator_updates,
        )  # fmt: skip
    except ConfigError as error:  # named by its field: the flag of that name
        parser.error(flag_words(error.named(flag_of(error.field))))
    except ValueError as error:  # a check that reads several fields says them itself
        parser.error(str(error))
    return args


def main(argv=None) -> dict:
    args = parse_args(argv)
    use_compile_cache(args)
    command = [*invoked_as("offline"), *args.argv]
    try:
        with signals_stop_at_a_checkpoint():  # a scheduler's SIGTERM stops it as Ctrl-C does
            if args.resume is not None:
                config = load_offline_config(args.resume)
                return run_offline(config, args.resume, resume=True, command=command,
                                   allow_unsealed=args.allow_unsealed)  # fmt: skip
            return run_offline(args.config, args.out, overwrite=args.overwrite, command=command)
    except RunError as error:
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        raise SystemExit(interrupted(args.out, "chunks")) from None
