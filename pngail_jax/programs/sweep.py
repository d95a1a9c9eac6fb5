"""The main job: every method x seed (x label ratio x noise) as one compiled program.

    python -m experiments.sweep        # smoke scale: Pendulum-v1, 7 methods x 3 seeds
    python -m experiments.sweep --preset check   # a first look: 20 iterations x 2 seeds
    python -m experiments.sweep --demos data/released/Pendulum-v1_mixture.npy \\
        --seeds 5 --iterations 1000
    python -m experiments.sweep --preset paper --demos ...   # 5,000 iterations, 5 seeds (GPU)
    python -m experiments.sweep --config runs/A/config.json --seeds 10   # a new run like A
    python -m experiments.sweep --resume runs/20261122-210000

The command line fills in a ``pngail_jax.config.run_config.RunConfig``. Without ``--demos`` the
demonstrations are made by ``pngail_jax.jobs.make_demos`` (1:4 optimal to intermediate
trajectories) once and reused from ``runs/demos-cache/<env>/`` (or
``$PNGAIL_JAX_DEMOS_CACHE/<env>/``). Writes to ``--out`` (default
``runs/<timestamp>``): ``config.json`` (the config, what it resolved to, and provenance),
``metrics.csv``, ``curves.png``, ``summary.md``, ``summary.json``, ``policies/<method>/``
(every seed's final policy, for ``pngail_jax.load_policy``) and ``checkpoints/`` (the whole
grid's state after every chunk; ``--resume DIR`` continues from the last one to the numbers
of an uninterrupted run).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

from pngail_jax.analysis.tracking import check_backends
from pngail_jax.config.run_config import PRESETS_BY_NAME, RunConfig
from pngail_jax.config.task import task_classifier
from pngail_jax.config.validation import ConfigError
from pngail_jax.jobs import record
from pngail_jax.jobs import sweep as sweep_job
from pngail_jax.jobs.errors import RunError
from pngail_jax.programs import flags
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

SMOKE = RunConfig.preset("smoke")
# Flags that --resume DIR accepts: the run's config.json has every other value.
RESUME_FLAGS = (
    "--resume",
    "--allow-changed-inputs",
    "--allow-unsealed",
    "--coordinator",
    "--num-processes",
    "--process-id",
    "--compile-cache",
    "--no-compile-cache",
)


@dataclasses.dataclass(frozen=True)
class Invocation:
    """What one command asks for: a config (None until a resumed run's is read), where to
    write, and how to start (multi-host, compilation cache)."""

    config: RunConfig | None
    out: Path
    resume: bool
    distributed: dict
    args: argparse.Namespace  # the parsed flags (compilation cache, ...)
    argv: list[str]


def build_parser() -> argparse.ArgumentParser:
    from pngail_jax.adversarial.methods import PRESETS

    methods_help = "\n".join(
        f"  {name:14s} {preset.description} (r: {preset.confidence_source})"
        for name, preset in PRESETS.items()
    )
    parser = ArgumentParser(
        "sweep",
        description=__doc__.split("\n\n")[0],
        epilog=f"methods:\n{methods_help}",
        formatter_class=HelpFormatter,
    )
    add = parser.add_argument
    add(
        "--env",
        help=f"{ENV_HELP} (default: the task of an authors' --demos file, e.g. Hopper-v4 for "
        f"Hopper-v2_mixture.npy; else {SMOKE.env})",
    )
    add(
        "--preset",
        choices=sorted(PRESETS_BY_NAME),
        help="named scale: "
        + "; ".join(f"{name} {values}" for name, values in PRESETS_BY_NAME.items())
        + " (default smoke); explicit flags override it",
    )
    add(
        "--config",
        type=path_argument,
        metavar="FILE",
        help="start a new run from a saved config.json (flags given override it) (default: none)",
    )
    flags.add_flags(parser, flags.RUN_FLAGS, defaults=SMOKE)
    flags.add_learner_flags(parser)
    _add_output_flags(add)
    flags.add_settings_flags(parser)
    add_compile_cache_flags(parser)
    _add_multihost_flags(parser)
    return parser


def _add_output_flags(add) -> None:
    """Where a run writes, and how it continues or replaces one."""
    add("--out", type=path_argument, help="output directory (default runs/<timestamp>)")
    add(
        "--overwrite",
        action="store_true",
        help="replace a sweep run already in --out (default: refuse; anything else there is "
        "always refused)",
    )
    add(
        "--resume",
        type=path_argument,
        metavar="DIR",
        help="continue DIR's run (default: a new run)",
    )
    add(
        "--allow-changed-inputs",
        action="store_true",
        help="with --resume: go on although a demonstration, confidence or cache file differs "
        "from the one the run began with (the run then mixes two data sets) (default: refuse)",
    )
    add_allow_unsealed(add, "with --resume: continue a run")


def _add_multihost_flags(parser) -> None:
    multihost = parser.add_argument_group(
        "multi-host (run the same command on every host; process 0 writes the outputs)"
    )
    multihost.add_argument(
        "--coordinator", help="host:port of process 0, for jax.distributed (default: one host)"
    )
    multihost.add_argument("--num-processes", type=int, help="(default: one host)")
    multihost.add_argument("--process-id", type=int, help="(default: one host)")


def parse_args(argv=None) -> Invocation:
    """The ``Invocation`` of the flags in ``argv``; exits naming the flag on a bad value."""
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    distributed = {
        "coordinator_address": args.coordinator,
        "num_processes": args.num_processes,
        "process_id": args.process_id,
    }
    given = [value is not None for value in distributed.values()]
    if any(given) and not all(given):
        parser.error("--coordinator, --num-processes and --process-id go together")
    if args.allow_changed_inputs and args.resume is None:
        parser.error("--allow-changed-inputs goes with --resume DIR")
    if args.allow_unsealed and args.resume is None:
        parser.error("--allow-unsealed goes with --resume DIR")
    if args.resume is not None:
        flags = [a.split("=")[0] for a in argv if a.startswith("--")]
        if any(flag not in RESUME_FLAGS for flag in flags):
            parser.error(
                "--resume DIR takes no other flags (except the multi-host ones): the run's "
                "config.json has them"
            )
        owner = output_owner(args.resume) if args.resume.is_dir() else None
        if owner not in (None, "sweep"):
            parser.error(f"--resume {args.resume} holds a run of experiments.{owner}, not a sweep")
        return Invocation(None, args.resume, True, distributed, args, argv)
    config = config_from_flags(parser, args)
    if args.coordinator is not None and config.demos is None:
        parser.error("multi-host runs need --demos (a file every host can read)")
    out = args.out if args.out is not None else Path("runs") / time.strftime("%Y%m%d-%H%M%S")
    claim_output(parser, out, "sweep", args.overwrite)
    return Invocation(config, out, False, distributed, args, argv)


def config_from_flags(parser, args) -> RunConfig:
    """The preset or saved config the flags name, with every flag given applied; exits
    naming the flag of a bad value."""
    if args.config is not None and args.preset is not None:
        parser.error("--config and --preset both set the starting point: give one")
    try:
        if args.config is not None:
            base = RunConfig.from_json(args.config)
        else:
            base = RunConfig.preset(args.preset or "smoke")
    except ValueError as error:
        parser.error(f"--{'config' if args.config else 'preset'}: {error}")
    given = flags.given_values(parser, args, flags.RUN_FLAGS)
    top = given.get("", {})
    if "methods" in top and "baseline" not in top and base.baseline not in top["methods"]:
        top["baseline"] = None  # a --config file's baseline that --methods leaves out
    env = check_env(parser, args.env or _task_of(args.demos) or base.env)
    if top.get("demos", base.demos) != base.demos:  # another data set: not the saved one's
        base = dataclasses.replace(
            base, conf=None, confidence_field=None, action_scale=None, random_return=None,
            optimal_return=None,
        )  # fmt: skip
    same_task = env == base.env
    settings = flags.settings_from_flags(parser, args, env, base.settings if same_task else None)
    # Another task: its own classifier, as RunConfig.replace gives.
    classifier = base.classifier if same_task else task_classifier(env)
    learner = flags.learner_from_flags(parser, args, base.learner)
    tables = [flags.RUN_FLAGS, flags.SETTINGS_FLAGS, flags.LEARNER_FLAGS]
    try:
        classifier = dataclasses.replace(classifier, **given.get("classifier", {}))
    except ConfigError as error:
        parser.error(flags.flag_message(error.nested("classifier"), tables))
    try:
        config = base.replace(
            env=env, settings=settings, classifier=classifier, learner=learner, **top
        )
    except ConfigError as error:
        parser.error(flags.flag_message(error, tables))
    except ValueError as error:  # a check between fields that names no single one
        parser.error(str(error))
    try:  # the log backends' packages, before any compile or directory
        check_backends(config.log)
    except ImportError as error:
        parser.error(f"log {list(config.log)}: {error}")
    return config


def _task_of(demos: str | None) -> str | None:
    """The task of an authors' released file (``Hopper-v2_mixture.npy``: Hopper-v4), so
    ``--demos`` alone picks it."""
    from pngail_jax.demos import released_task

    return None if demos is None else released_task(demos)


# -- starting: devices, compilation cache, multi-host; then the sweep job ----------------------


def start(invocation: Invocation) -> tuple[RunConfig, record.SavedRun | None]:
    """Reads a resumed run's config, sets up devices, compilation cache and multi-host.

    Returns the config and the saved run (None for a new one).
    """
    saved = (
        record.load_saved(invocation.out, invocation.args.allow_unsealed)
        if invocation.resume
        else None
    )
    config = saved.config if saved else invocation.config
    cpu_devices = config.cpu_devices
    if saved and cpu_devices is None and saved.platform == "cpu":
        cpu_devices = saved.local_device_count  # the same sharding as before
    sweep_job.configure_devices(cpu_devices)
    import jax

    use_compile_cache(invocation.args)
    if invocation.distributed["coordinator_address"] is not None:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(**invocation.distributed)
        if jax.process_index() != 0:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  process 0 reports
    return config, saved


def main(argv=None, own_interrupt: bool = True) -> Path:
    """Runs the sweep of ``argv`` (``pngail_jax.jobs.sweep.run``). ``own_interrupt``: Ctrl-C ends
    in one line saying how to continue (a caller that runs several sweeps, as
    experiments.paper, passes False and says it in its own words)."""
    invocation = parse_args(argv)
    try:
        config, saved = start(invocation)
        with signals_stop_at_a_checkpoint():  # a scheduler's SIGTERM stops it as Ctrl-C does
            sweep_job.run(
                None if saved else config,
                invocation.out,
                resume=saved is not None,
                overwrite=invocation.args.overwrite,
                allow_changed_inputs=invocation.args.allow_changed_inputs,
                command=[*invoked_as("sweep"), *invocation.argv],
                saved=saved,
            )
    except RunError as error:
        raise SystemExit(str(error)) from None
    except KeyboardInterrupt:
        if not own_interrupt:
            raise
        raise SystemExit(interrupted(invocation.out)) from None
    return invocation.out
