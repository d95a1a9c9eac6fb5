"""The main job: every method x seed (x label ratio x noise) as one compiled program.

    python -m experiments.sweep        # smoke scale: Pendulum-v1, 7 methods x 3 seeds
    python -m experiments.sweep --preset check   # a first look: 20 iterations x 2 seeds
    python -m experiments.sweep --demos data/released/Pendulum-v1_mixture.npy \\
        --seeds 5 --iterations 1000
    python -m experiments.sweep --preset paper --demos ...   # 5,000 iterations, 5 seeds (GPU)
    python -m experiments.sweep --config runs/A/config.json --seeds 10   # a new run like A
    python -m experiments.sweep --resume runs/20261122-210000

The command line fills in a ``pngail_jax.run_config.RunConfig``. Without ``--demos`` the
demonstrations are made by ``experiments.make_demos`` (1:4 optimal to intermediate
trajectories) once and reused from ``runs/demos-cache/<env>/``. Writes to ``--out`` (default
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
import shutil
import sys
import time
from pathlib import Path

import numpy as np

from experiments.cli import (
    ENV_HELP,
    MARKER,
    ArgumentParser,
    HelpFormatter,
    RunLocked,
    check_env,
    claim_output,
    comma_floats,
    known_names,
    output_owner,
    output_refusal,
    path_argument,
    prepare_output,
    run_lock,
    text_argument,
    ticking,
)
from pngail_jax import compilation
from pngail_jax import settings as run_settings
from pngail_jax.run_config import (
    FISHER_FORMS,
    LOG_BACKENDS,
    PRESETS_BY_NAME,
    RunConfig,
    task_classifier,
    upgrade_saved_config,
)
from pngail_jax.tracking import check_backends

DEMO_CACHE = Path("runs") / "demos-cache"
MINARI_PREFIX = "minari:"
SMOKE = RunConfig.preset("smoke")
# Flags that --resume DIR accepts: the run's config.json has every other value.
RESUME_FLAGS = (
    "--resume",
    "--allow-changed-inputs",
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
    from pngail_jax.methods import ALL_METHOD_NAMES, METHOD_NAMES, PRESETS

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
        "--methods",
        help=f"comma-separated, from {', '.join(ALL_METHOD_NAMES)} (default: the paper's "
        f"seven, {', '.join(METHOD_NAMES)})",
    )
    add("--seeds", type=int, help=f"seeds per method and setting (default {SMOKE.seeds})")
    add("--iterations", type=int, help=f"TRPO iterations per run (default {SMOKE.iterations})")
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
    _add_demonstration_flags(add)
    add(
        "--num-demos",
        type=int,
        help="rows per split, n_c + n_u (default: the task's Table 3 size, capped at the "
        "demonstrations' rows; every row for a task without one)",
    )
    add("--label-ratio", help="comma-separated values: a grid axis (default 0.2)")
    add("--noise", help="confidence noise std, comma-separated: a grid axis (default 0)")
    add("--seed", type=int, help="base PRNG seed (default 0)")
    add(
        "--chunk-iterations",
        type=int,
        help="iterations per compiled chunk: progress, checkpoint, log "
        f"(default {SMOKE.chunk_iterations})",
    )
    add(
        "--classifier-steps",
        type=int,
        help=f"confidence classifier steps (default {SMOKE.classifier.num_steps:,}; "
        f"{task_classifier('Walker2d').num_steps:,} on Walker2d, the paper's)",
    )
    add("--bsc-eps", type=float, help="BSC's clip (default 0.01; 0.05 on Walker2d, the paper's)")
    add(
        "--fisher",
        choices=FISHER_FORMS,
        help="Fisher-vector product: the same matrix either way (the Hessian of the mean KL at "
        "the current policy); gauss_newton is 1.7x faster here (default gauss_newton)",
    )
    add(
        "--fisher-subsample",
        type=int,
        help="Fisher products on every k-th time step (default 1: all)",
    )
    add(
        "--cpu-devices",
        type=int,
        help="on a CPU, split it into this many XLA devices and shard the grid over them "
        "(default 1: on 2 cores one device already uses both, and 2 measured no faster)",
    )
    add(
        "--log",
        help=f"comma-separated logging backends, from {', '.join(LOG_BACKENDS)}, fed once per "
        "chunk (default: none)",
    )
    _add_output_flags(add)
    run_settings.add_arguments(parser)
    compilation.add_arguments(parser)
    _add_multihost_flags(parser)
    return parser


def _add_demonstration_flags(add) -> None:
    """The flags that name the demonstrations and how to read them."""
    add(
        "--demos",
        type=text_argument,
        help="*_mixture.npy (authors' layout), *.npz, or minari:<dataset id> "
        "(default: made by experiments.make_demos and cached)",
    )
    add(
        "--conf",
        type=text_argument,
        help="confidence file (default: the mixture's sibling; per episode for Minari)",
    )
    add(
        "--confidence-field",
        help="Minari: the per-episode field holding confidences (default: none)",
    )
    add(
        "--action-scale",
        type=float,
        help="multiplies stored actions (default: an authors' file's known scale, 2 for "
        "their Pendulum file, whose torques are stored halved; else 1)",
    )
    add(
        "--optimal-return",
        type=float,
        help="the normalised return's 1: the best return the task allows (default: the "
        "demonstrations' own, Table 3 for an authors' file; none for a file of rows)",
    )
    add(
        "--random-return",
        type=float,
        help="the normalised return's 0 (default: the demonstrations' own; with "
        "--optimal-return alone, measured from uniform random actions)",
    )


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
    """The preset or saved config the flags name, with every flag given applied."""
    from pngail_jax.methods import ALL_METHOD_NAMES

    if args.config is not None and args.preset is not None:
        parser.error("--config and --preset both set the starting point: give one")
    try:
        if args.config is not None:
            base = RunConfig.from_json(args.config)
        else:
            base = RunConfig.preset(args.preset or "smoke")
    except ValueError as error:
        parser.error(f"--{'config' if args.config else 'preset'}: {error}")
    demos = args.demos
    env = check_env(parser, args.env or _task_of(demos) or base.env)
    if demos is not None and not demos.startswith(MINARI_PREFIX):
        if not Path(demos).exists():
            parser.error(f"--demos {demos} does not exist")
        demos = str(Path(demos).absolute())
    if args.conf is not None and not Path(args.conf).exists():
        parser.error(f"--conf {args.conf} does not exist")
    conf = None if args.conf is None else str(Path(args.conf).absolute())
    log = None
    if args.log is not None:
        log = tuple(known_names(parser, args.log, LOG_BACKENDS, "log backend", flag="--log"))
        try:
            check_backends(log)
        except ImportError as error:
            parser.error(f"--log: {error}")
    if demos is not None and demos != base.demos:  # another data set: not the saved one's
        base = dataclasses.replace(
            base,
            conf=None,
            confidence_field=None,
            action_scale=None,
            random_return=None,
            optimal_return=None,
        )
    try:
        settings_base = base.settings if env == base.env else None
        settings = run_settings.from_arguments(env, args, base=settings_base)
        # Another task: its own settings row and classifier, as RunConfig.replace gives.
        classifier = base.classifier if env == base.env else task_classifier(env)
        if args.classifier_steps is not None:
            classifier = dataclasses.replace(classifier, num_steps=args.classifier_steps)
        overrides = dict(
            env=env,
            settings=settings,
            methods=None
            if args.methods is None
            else tuple(
                known_names(parser, args.methods, ALL_METHOD_NAMES, "method", flag="--methods")
            ),
            seeds=args.seeds,
            iterations=args.iterations,
            label_ratios=comma_floats(parser, "--label-ratio", args.label_ratio),
            noise_stds=comma_floats(parser, "--noise", args.noise),
            seed=args.seed,
            demos=demos,
            conf=conf,
            confidence_field=args.confidence_field,
            action_scale=args.action_scale,
            random_return=args.random_return,
            optimal_return=args.optimal_return,
            num_demos=args.num_demos,
            chunk_iterations=args.chunk_iterations,
            classifier=classifier,
            bsc_eps=args.bsc_eps,
            fisher=args.fisher,
            fisher_subsample=args.fisher_subsample,
            cpu_devices=args.cpu_devices,
            log=log,
        )
        config = base.replace(**{k: v for k, v in overrides.items() if v is not None})
    except ValueError as error:
        parser.error(_flag_message(str(error)))
    try:  # a --config file's log backends too, before any compile or directory
        check_backends(config.log)
    except ImportError as error:
        parser.error(f"log {list(config.log)}: {error}")
    return config


def _task_of(demos: str | None) -> str | None:
    """The task of an authors' released file (``Hopper-v2_mixture.npy``: Hopper-v4), so
    ``--demos`` alone picks it."""
    from pngail_jax.demos import released_task

    return None if demos is None else released_task(demos)


def _flag_message(message: str) -> str:
    """A RunConfig error in the command line's words (field names as flags)."""
    for field, flag in (
        ("label ratios", "--label-ratio values"),
        ("noise stds", "--noise values"),
        ("iterations (", "--iterations ("),
        ("iterations must", "--iterations must"),
        ("methods must", "--methods must"),
        ("seeds must", "--seeds must"),
        ("chunk_iterations", "--chunk-iterations"),
        ("fisher_subsample", "--fisher-subsample"),
        ("cpu_devices", "--cpu-devices"),
        ("num_demos", "--num-demos"),
        ("action_scale", "--action-scale"),
        ("random_return", "--random-return"),
        ("optimal_return", "--optimal-return"),
        ("bsc_eps", "--bsc-eps"),
        ("ClassifierConfig.num_steps", "--classifier-steps"),
        ("seed must", "--seed must"),
        ("conf:", "--conf:"),
        ("confidence_field", "--confidence-field"),
        ("demos:", "--demos:"),
    ):
        if message.startswith(field):
            return flag + message[len(field) :]
    return message


# -- starting: a new run's config, or a resumed run's ---------------------------------------


@dataclasses.dataclass
class SavedRun:
    """A resumed run's config.json: its config, the demonstrations it used, its devices."""

    config: RunConfig
    demos_path: str
    device_count: int
    platform: str
    local_device_count: int
    inputs: dict  # {role: integrity.file_record} of the input files; {} from older versions
    normalizer: list[float] | None = None  # what the run normalised returns by


SEAL = ".config.sealed.json"


def sealed_part(document: dict) -> dict:
    """What config.json's seal covers: everything but provenance (where it ran)."""
    return {key: value for key, value in document.items() if key != "provenance"}


def check_seal(directory: Path, document: dict) -> None:
    """Refuses a config.json that differs from the seal written when the run began, naming
    each changed field; a run from before seals exists goes on with a note."""
    from pngail_jax.integrity import IntegrityError, sealed_differences

    try:
        changes = sealed_differences(directory / SEAL, sealed_part(document))
    except IntegrityError as error:
        raise SystemExit(f"--resume {directory}: {error}") from None
    if changes is None:
        if (directory / MARKER).exists():  # made by a version that seals: the seal was removed
            raise SystemExit(
                f"--resume {directory}: its seal {SEAL} is missing, so config.json cannot be "
                "checked; restore it, or start a new run"
            )
        print(f"note: {directory}/config.json has no seal (an older version made the run)")
    elif changes:
        raise SystemExit(
            f"--resume {directory}: config.json was changed since the run began ("
            + "; ".join(changes[:5])
            + (f"; and {len(changes) - 5} more" if len(changes) > 5 else "")
            + "): a run keeps what it began with; restore the file, or start a new run from "
            "it with --config"
        )


def load_saved(directory: Path) -> SavedRun:
    from pngail_jax.integrity import IntegrityError, read_json

    path = directory / "config.json"
    if not path.exists():
        raise SystemExit(f"--resume {directory}: no config.json there")
    try:
        raw = read_json(path, "run config")
    except IntegrityError as error:
        raise SystemExit(f"--resume {directory}: {error}") from None
    if isinstance(raw, dict):
        check_seal(directory, raw)
    try:
        data = upgrade_saved_config(raw)
        config = RunConfig.from_dict(data)
        # The engine that ran goes on running (a run begun on a CPU resumed on a GPU would
        # otherwise switch to MJX, whose state the checkpoint does not hold).
        physics = data["resolved"].get("physics")
        if physics is not None and config.settings.physics is None:
            config = config.replace(settings=config.settings.replace(physics=physics))
        devices = data["provenance"]
        return SavedRun(
            config,
            data["resolved"]["demos_path"],
            devices["device_count"],
            devices["platform"],
            devices["local_device_count"],
            data["resolved"].get("inputs", {}),
            data["resolved"].get("normalizer"),
        )
    except IntegrityError as error:
        raise SystemExit(f"--resume {directory}: {error}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as error:
        raise SystemExit(
            f"--resume {directory}: {path} is damaged or not a run config ({error!r})"
        ) from None


def check_inputs(saved: SavedRun, allow_changed: bool) -> None:
    """Refuses to resume on input files that differ from those the run began with."""
    from pngail_jax.integrity import changed_inputs

    changes = changed_inputs(saved.inputs)
    if not changes:
        return
    listing = "; ".join(changes)
    if not allow_changed:
        raise SystemExit(
            f"cannot resume: {listing}. The rest of the run would train on other data than "
            "its start. Restore the file, or pass --allow-changed-inputs to go on anyway."
        )
    print(f"WARNING: {listing}; going on (--allow-changed-inputs): the run mixes data sets")


def minari_directory(dataset_id: str) -> Path | None:
    """Where Minari keeps a local dataset (``MINARI_DATASETS_PATH``, default
    ``~/.minari/datasets``), or None when it is not there."""
    root = Path(os.environ.get("MINARI_DATASETS_PATH", "~/.minari/datasets")).expanduser()
    directory = root / dataset_id
    return directory if directory.is_dir() else None


def input_files(config: RunConfig, demos_path: str) -> dict:
    """``{role: integrity.file_record}`` of the files a run reads its demonstrations from
    (a local Minari dataset by its whole directory)."""
    from pngail_jax.demos import released_confidence_path
    from pngail_jax.integrity import file_record

    if demos_path.startswith(MINARI_PREFIX):
        files = {"confidence file": config.conf} if config.conf else {}
        dataset = minari_directory(demos_path.removeprefix(MINARI_PREFIX))
        if dataset is not None:  # its content, not only its id: a rebuilt dataset differs
            files["Minari dataset"] = dataset
    else:
        files = {"demonstrations": demos_path}
        if config.conf or demos_path.endswith("_mixture.npy"):
            files["confidence file"] = config.conf or released_confidence_path(demos_path)
    return {role: file_record(path) for role, path in files.items()}


def configure_devices(requested: int | None) -> None:
    """Splits the CPU into ``requested`` XLA devices (before JAX starts its backend).

    Not by default: benchmarks/grid_throughput.py measured a 35-cell grid on 2 cores at
    89.9k steps/s on one device and 90.9k on two (one XLA CPU device already uses every core).
    """
    import jax

    if requested is not None and requested > 1:
        jax.config.update("jax_num_cpu_devices", requested)


def start(invocation: Invocation) -> tuple[RunConfig, SavedRun | None, bool]:
    """Reads a resumed run's config, sets up devices, compilation cache and multi-host.

    Returns the config, the saved run (None for a new one) and whether this process writes.
    """
    saved = load_saved(invocation.out) if invocation.resume else None
    config = saved.config if saved else invocation.config
    cpu_devices = config.cpu_devices
    if saved and cpu_devices is None and saved.platform == "cpu":
        cpu_devices = saved.local_device_count  # the same sharding as before
    configure_devices(cpu_devices)
    import jax

    compilation.from_arguments(invocation.args)
    if invocation.distributed["coordinator_address"] is not None:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(**invocation.distributed)
        if jax.process_index() != 0:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115  process 0 reports
    if saved and saved.device_count != len(jax.devices()):
        print(
            f"WARNING: resuming on {len(jax.devices())} devices, the run began on "
            f"{saved.device_count}: a different sharding can change the last bits, and "
            "the rest of the run with them"
        )
    return config, saved, jax.process_index() == 0


# -- building the grid ----------------------------------------------------------------------


@dataclasses.dataclass
class SweepRun:
    """A compiled grid and what its outputs need."""

    config: RunConfig
    env: object
    trainer: object
    cells: list
    grid: object
    demos_path: str
    normalizer: list[float] | None
    action_scale: float = 1.0  # what the stored actions were multiplied by
    normalizer_source: str = "none"


def load_or_make_demos(config: RunConfig, saved_path: str | None = None, env=None):
    """The demonstrations and the path they came from (made and cached without ``demos``);
    a file of rows that is not an authors' one is split by ``env``'s sizes."""
    from pngail_jax.demos import load_demonstrations

    source = saved_path or config.demos
    if source is not None:
        demos = load_demonstrations(
            source,
            config.conf,
            config.action_scale,
            confidence_field=config.confidence_field,
            observation_size=None if env is None else env.observation_size,
            action_size=None if env is None else env.action_size,
        )
        return demos, source
    from pngail_jax.demos import DemonstrationError

    cached = DEMO_CACHE / config.env / "demos.npz"
    remake = []
    if cached.exists():
        try:
            demos = load_demonstrations(cached)
            print(f"reusing demonstrations {cached}", flush=True)
            return demos, str(cached.absolute())
        except DemonstrationError as error:
            print(f"the cached demonstrations are damaged: {error}; making them again")
            remake = ["--overwrite"]
    else:
        print(f"no --demos: making them with experiments.make_demos into {cached.parent}")
    from experiments import make_demos

    # The cache is the sweep's own: a make_demos run cut short there is replaced.
    remake = ["--overwrite"] if cached.parent.exists() else remake
    make_demos.main(["--env", config.env, "--out", str(cached.parent), *remake])
    return load_demonstrations(cached), str(cached.absolute())


def normalizer_of(demos) -> list[float] | None:
    metadata = demos.metadata
    if "random_return" in metadata and "optimal_return" in metadata:
        return [float(metadata["random_return"]), float(metadata["optimal_return"])]
    return None


RANDOM_RETURN_EPISODES = 32


def resolve_normalizer(config: RunConfig, demos, env) -> tuple[list[float] | None, str]:
    """(random, optimal) returns and where they came from: the flags, the demonstrations'
    metadata, or the flag's optimal return with a random return measured here (uniform
    random actions, ``RANDOM_RETURN_EPISODES`` episodes, a key of ``config.seed``)."""
    if config.optimal_return is None:
        normalizer = normalizer_of(demos)
        source = demos.metadata.get("normalizer_source", "the demonstrations' metadata")
        return normalizer, source if normalizer else "none"
    if config.random_return is not None:
        return [config.random_return, config.optimal_return], "--random-return, --optimal-return"
    import jax

    from pngail_jax.demos.generate import random_policy_return

    key = jax.random.fold_in(jax.random.key(config.seed), 7)
    random_return = random_policy_return(env, key, RANDOM_RETURN_EPISODES)
    if not config.optimal_return > random_return:
        raise SystemExit(
            f"--optimal-return {config.optimal_return:g} is not above the random policy's "
            f"return, {random_return:.1f} (measured): give the best return the task allows"
        )
    return [random_return, config.optimal_return], (
        f"--optimal-return; random return measured ({RANDOM_RETURN_EPISODES} episodes of "
        "uniform random actions)"
    )


def blocks_per_chunk(num_evaluations: int, target_blocks: int) -> int:
    """The largest divisor of num_evaluations not above the target (so all chunks match)."""
    return max(
        d for d in range(1, min(target_blocks, num_evaluations) + 1) if not num_evaluations % d
    )


def build(config: RunConfig, saved: SavedRun | None) -> SweepRun:
    """Environment, demonstrations, trainer and the compiled grid of ``config``."""
    import jax

    from pngail_jax.demos import DemonstrationError
    from pngail_jax.grid import Grid, make_cells, stack_cells
    from pngail_jax.train import AdversarialTrainer

    try:
        env = run_settings.make_env(config.env, config.settings)
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise SystemExit(f"environment: {error}") from None
    try:
        demos, demos_path = load_or_make_demos(config, saved.demos_path if saved else None, env)
    except (DemonstrationError, FileNotFoundError, ImportError) as error:
        raise SystemExit(f"demonstrations: {error}") from None
    try:
        trainer = AdversarialTrainer(config.adversarial_config(demos.num_rows), env, demos)
        trainer.check_methods(config.methods)
        trainer.check_label_ratios(config.label_ratios)
    except DemonstrationError as error:
        raise SystemExit(f"{demos_path}: {error}") from None
    for ratio in config.label_ratios:
        num_labelled = round(ratio * trainer.num_demos)
        if not 0 < num_labelled < trainer.num_demos:
            raise SystemExit(
                f"--label-ratio {ratio} labels {num_labelled} of {trainer.num_demos} rows; "
                "need at least one labelled and one unlabelled row"
            )
    cells = make_cells(config.methods, config.seeds, config.label_ratios, config.noise_stds)
    inputs = stack_cells(cells, jax.random.key(config.seed), {"bsc_eps": config.task_bsc_eps})
    eval_every = config.settings.eval_every
    num_evaluations = config.iterations // eval_every
    chunk_blocks = blocks_per_chunk(num_evaluations, max(1, config.chunk_iterations // eval_every))
    devices = jax.devices()
    if saved is not None and saved.normalizer is not None:  # as the run began
        normalizer, normalizer_source = saved.normalizer, "the run's config.json"
    else:
        normalizer, normalizer_source = resolve_normalizer(config, demos, env)
    print(
        f"{len(cells)} runs ({', '.join(config.methods)} x {config.seeds} seeds x "
        f"{config.num_settings} setting(s)) on {config.env}, {config.iterations} iterations x "
        f"{config.settings.samples_per_iteration} steps, {trainer.num_demos} demonstration "
        f"rows; {len(devices)} {devices[0].platform} device(s)\n"
        f"  {run_settings.describe(config.settings, env)}",
        flush=True,
    )
    announce_inputs(demos, trainer, normalizer, normalizer_source, config, saved)
    with ticking("compiling"):
        grid = Grid(trainer, inputs, chunk_blocks, devices)
    print(
        f"compiled in {grid.compile_seconds:.1f} s ({grid.num_cells} cells"
        f"{f', padded to {grid.num_padded}' if grid.num_padded != grid.num_cells else ''}, "
        f"{grid.iterations_per_chunk} iterations per chunk)",
        flush=True,
    )
    action_scale = float(demos.metadata.get("action_scale", 1.0))
    return SweepRun(
        config, env, trainer, cells, grid, demos_path, normalizer, action_scale, normalizer_source
    )


def announce_inputs(demos, trainer, normalizer, normalizer_source, config, saved) -> None:
    """The notes on what the run reads: its normaliser, an applied action scale, clipped
    demonstration actions."""
    from pngail_jax.demos import action_scale_note

    if normalizer is None:
        print(
            "note: the demonstrations carry no random/optimal returns: no normalised return "
            "(give --optimal-return, and --random-return or it is measured)"
        )
    elif config.optimal_return is not None and saved is None:
        print(
            f"normalised return: random {normalizer[0]:.1f}, optimal {normalizer[1]:.1f} "
            f"({normalizer_source})"
        )
    if action_scale_note(demos):
        print(action_scale_note(demos))
    if trainer.num_clipped_rows:
        print(
            f"note: {trainer.num_clipped_rows} of {demos.num_rows} demonstration rows have "
            "actions beyond the bounds; the discriminator sees them clipped, as the agent's "
            "(docs/methods.md)"
        )


def write_config(out: Path, run: SweepRun, argv: list[str]) -> None:
    """config.json: the RunConfig, what it resolved to (with the SHA-256 of every input file,
    which ``--resume`` checks), and provenance."""
    from pngail_jax.integrity import seal, write_json
    from pngail_jax.run_config import provenance

    document = {
        **run.config.to_dict(),
        "resolved": {
            "demos_path": run.demos_path,
            "normalizer": run.normalizer,
            "normalizer_source": run.normalizer_source,
            "action_scale": run.action_scale,
            "num_demos": run.trainer.num_demos,
            "bsc_eps": run.config.task_bsc_eps,
            # The engine that ran (RunSettings.physics None: chosen from the platform).
            "physics": getattr(run.env, "physics", None),
            "adversarial": dataclasses.asdict(run.trainer.config),
            "inputs": input_files(run.config, run.demos_path),
        },
        "provenance": provenance(argv, "experiments.sweep"),
    }
    # What the run is created with, apart from the file a user may edit: every resume
    # compares config.json with it (provenance aside) and refuses a change, naming it.
    # Sealed first, so that a config.json never exists without its seal.
    seal(out / SEAL, sealed_part(document))
    write_json(out / "config.json", document)


# -- running chunks with progress and checkpoints --------------------------------------------


@dataclasses.dataclass
class Progress:
    """What a run has done: chunks, metrics so far (float[G, I]), the timing of its chunks."""

    chunks_done: int
    init_metrics: dict
    metrics: dict | None
    timing: dict

    def iterations_done(self, grid) -> int:
        return self.chunks_done * grid.iterations_per_chunk


def initial_state(run: SweepRun, checkpoint: Path | None):
    """The grid's state and progress: from ``checkpoint`` (an intact ``chunk_*`` directory,
    ``intact_checkpoint``) when resuming, else fresh."""
    import jax

    from pngail_jax.checkpoint import restore_tree
    from pngail_jax.integrity import read_json

    grid = run.grid
    start = time.perf_counter()
    state, init_metrics = grid.init()
    progress = Progress(0, grid.fetch(init_metrics), None, {"seconds": 0.0, "steps": 0})
    if checkpoint is not None:
        template = jax.eval_shape(lambda: grid.unpad(state))
        try:
            state = grid.place(restore_tree(checkpoint / "state", template))
        except ValueError as error:  # intact, but of another grid
            raise SystemExit(f"cannot resume from {checkpoint}: {error}") from None
        with np.load(checkpoint / "metrics.npz") as stored:
            progress.metrics = {name.replace(":", "/"): stored[name] for name in stored.files}
        done = read_json(checkpoint / "progress.json", "progress record")
        progress.chunks_done, progress.timing = done["chunks_done"], done["timing"]
        print(f"resumed from {checkpoint} (iteration {progress.iterations_done(grid)})")
        return state, progress
    mae = progress.init_metrics["confidence/mae"]
    print(
        f"classifier phase done in {time.perf_counter() - start:.1f} s (confidence MAE on D_u: "
        + ", ".join(
            f"{m} {np.mean(mae[[c.method == m for c in run.cells]]):.3f}"
            for m in run.config.methods
        )
        + ")",
        flush=True,
    )
    return state, progress


def run_chunks(run: SweepRun, out: Path, state, progress: Progress, writer: bool, logger=None):
    """Runs the remaining chunks: progress lines, a checkpoint and partial outputs after each."""
    from pngail_jax.grid import nonfinite_cells

    grid, config = run.grid, run.config
    num_chunks = config.iterations // grid.iterations_per_chunk
    reported_bad: set[int] = set()
    host_state = None
    for chunk in range(progress.chunks_done, num_chunks):
        chunk_start = time.perf_counter()
        state, chunk_metrics = grid.run_chunk(state)
        chunk_metrics = grid.fetch(chunk_metrics)
        progress.timing["seconds"] += time.perf_counter() - chunk_start
        # The cumulative seconds at each chunk's end (metrics.csv's wall clock); a run begun
        # by an older version has none for its first chunks, and gets none.
        chunk_ends = progress.timing.setdefault("chunk_seconds", [None] * chunk)
        chunk_ends.append(progress.timing["seconds"])
        progress.timing["steps"] += (
            len(run.cells) * grid.iterations_per_chunk * config.settings.samples_per_iteration
        )
        if progress.metrics is None:
            progress.metrics = chunk_metrics
        else:
            progress.metrics = {
                name: np.concatenate([progress.metrics[name], chunk_metrics[name]], axis=1)
                for name in chunk_metrics
            }
        progress.chunks_done = chunk + 1
        iteration = progress.iterations_done(grid)
        bad = set(nonfinite_cells(progress.metrics, config.settings.eval_every).tolist())
        for index in sorted(bad - reported_bad):
            cell = run.cells[index]
            print(f"  ! cell {cell.method} seed {cell.seed} ({cell.setting}) diverged (NaN/inf)")
        reported_bad |= bad
        rate = progress.timing["steps"] / progress.timing["seconds"]
        remaining = (num_chunks - chunk - 1) * progress.timing["seconds"] / (chunk + 1)
        print(
            f"iter {iteration:5d}/{config.iterations}  env steps "
            f"{iteration * config.settings.samples_per_iteration:,}/run  {rate:,.0f} steps/s  "
            f"ETA {format_seconds(remaining)}  "
            f"best {_best_cell(run.cells, chunk_metrics, run.normalizer)}",
            flush=True,
        )
        if logger is not None:
            logger.log_chunk(run.cells, chunk_metrics, iteration - grid.iterations_per_chunk + 1)
        # Every process takes part in the gather and in orbax's save (it synchronises them).
        host_state = grid.fetch(state)
        _save_checkpoint(out / "checkpoints", progress, host_state, writer)
        if writer and progress.chunks_done < num_chunks:  # partial results; the last below
            write_outputs(out, run, progress)
    return grid.fetch(state) if host_state is None else host_state


def format_seconds(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 60}m{seconds % 60:02d}s" if seconds >= 60 else f"{seconds}s"


def _best_cell(cells, chunk_metrics, normalizer) -> str:
    from pngail_jax.report import normalize

    final = chunk_metrics["eval/return"][:, -1]
    if not np.isfinite(final).any():
        return "(none finite)"
    index = int(np.nanargmax(final))
    cell = cells[index]
    normalized = normalize(final[index], normalizer)
    extra = f" ({normalized:.2f})" if np.isfinite(normalized) else ""
    return f"{cell.method}/seed {cell.seed} {final[index]:.1f}{extra}"


def intact_checkpoint(directory: Path) -> Path | None:
    """The newest ``chunk_*`` checkpoint in ``directory`` whose files match their digests,
    saying which newer ones are damaged or incomplete and left aside; None if there is none."""
    from pngail_jax.integrity import IntegrityError, verify_manifest

    candidates = sorted(directory.glob("chunk_*"), reverse=True) if directory.exists() else []
    for index, candidate in enumerate(candidates):
        try:
            verify_manifest(candidate)
        except IntegrityError as error:
            following = candidates[index + 1].name if index + 1 < len(candidates) else None
            print(
                f"checkpoint {candidate.name} is damaged or incomplete: {error}; "
                + (f"trying {following}" if following else "no older checkpoint to fall back on")
            )
            continue
        return candidate
    print(f"no intact checkpoint in {directory}: starting from the beginning")
    return None


def _save_checkpoint(directory: Path, progress: Progress, host_state, writer: bool):
    """Writes chunk_NNNN/ (state via orbax, metrics, progress, then the digests that mark it
    complete) and keeps the last two, so a damaged newest one leaves an older one to resume.

    Every process calls it (orbax synchronises processes); only the writer writes the rest.
    """
    from pngail_jax.checkpoint import save_tree
    from pngail_jax.integrity import atomic_path, write_json, write_manifest

    path = directory / f"chunk_{progress.chunks_done:04d}"
    try:
        save_tree(path / "state", host_state)
        if not writer:
            return
        metrics = {name.replace("/", ":"): value for name, value in progress.metrics.items()}
        with atomic_path(path / "metrics.npz") as temporary:
            np.savez(temporary, **metrics)
        write_json(
            path / "progress.json",
            {"chunks_done": progress.chunks_done, "timing": progress.timing},
        )
        write_manifest(path)
    except OSError as error:  # a full disk, a lost mount: one line, and no half checkpoint
        shutil.rmtree(path, ignore_errors=True)
        for partial in directory.glob("*.orbax-checkpoint-tmp*"):
            shutil.rmtree(partial, ignore_errors=True)
        raise SystemExit(
            f"cannot write checkpoint {path}: {error.strerror or error}; the chunks before it "
            f"are kept: free space (or fix the disk), then --resume {directory.parent}"
        ) from None
    for old in sorted(directory.glob("chunk_*"))[:-2]:
        shutil.rmtree(old)


# -- outputs ----------------------------------------------------------------------------------


def _title(config: RunConfig, num_cells: int) -> str:
    return f"{config.env}: {num_cells} runs, {config.iterations} iterations"


def write_outputs(out: Path, run: SweepRun, progress: Progress) -> str:
    """metrics.csv, curves.png, summary.json and summary.md of the iterations done so far
    (summary.json's ``complete`` is false and ``iterations_done`` says how far until the run
    ends); returns summary.md's text."""
    from pngail_jax import report
    from pngail_jax.grid import nonfinite_cells

    config, cells = run.config, run.cells
    metrics = {**progress.metrics, **progress.init_metrics}
    chunk_seconds = progress.timing.get("chunk_seconds", [])
    known = chunk_seconds if None not in chunk_seconds else ()
    report.write_metrics_csv(out / "metrics.csv", cells, metrics, run.normalizer, known)
    title = _title(config, len(cells))
    diverged = nonfinite_cells(progress.metrics, config.settings.eval_every)
    report.plot_curves(out / "curves.png", cells, metrics, run.normalizer, title, diverged)
    done = progress.iterations_done(run.grid)
    summary = {
        "complete": done == config.iterations,
        "iterations_done": done,
        "iterations": config.iterations,
        **report.summarize(
            cells,
            metrics,
            run.normalizer,
            progress.timing["steps"] / progress.timing["seconds"],
            run.grid.compile_seconds,
            excluded=diverged,
        ),
    }
    notes = [
        f"Diverged (NaN/inf), left out of the statistics: {cells[i].method} seed "
        f"{cells[i].seed} ({cells[i].setting})."
        for i in diverged
    ]
    if done < config.iterations:
        notes.append(f"Partial: {done} of {config.iterations} iterations so far.")
    if config.iterations < 1000:
        notes.append(
            f"A reduced budget ({config.iterations} iterations); the paper's is "
            "`--preset paper` (5,000 iterations, GPU)."
        )
    markdown = report.summary_markdown(summary, cells, metrics, title, notes)
    report.write_summary(out, summary, markdown)
    return markdown


def export_policies(out: Path, run: SweepRun, host_state, progress: Progress, writer: bool):
    """policies/<method>/ (and /<setting>/ when the grid has several): every seed's final
    policy, loadable with ``pngail_jax.load_policy`` (best seed by default; diverged seeds
    never are). Every process calls it (orbax synchronises them); the writer writes the JSON."""
    import jax

    from pngail_jax.checkpoint import save_trpo_policies
    from pngail_jax.grid import nonfinite_cells
    from pngail_jax.report import group_cells

    final_returns = progress.metrics["eval/return"][:, -1].copy()
    final_returns[nonfinite_cells(progress.metrics, run.config.settings.eval_every)] = np.nan
    trpo_state = run.trainer.policy_state(host_state)
    settings, groups = group_cells(run.cells)
    written = []
    for rows in groups.values():
        method, setting = run.cells[rows[0]].method, run.cells[rows[0]].setting
        directory = out / "policies" / method
        if len(settings) > 1:
            directory = directory / setting
        seeds_state = jax.tree.map(lambda x, rows=rows: x[np.asarray(rows)], trpo_state)
        extra = {
            "method": method,
            "setting": setting,
            "seeds": [run.cells[i].seed for i in rows],
            "env_options": run.config.settings.env_options,
        }
        written.append(
            save_trpo_policies(
                directory,
                run.env,
                run.trainer.config.trpo,
                seeds_state,
                final_returns[rows],
                extra,
                write_metadata=writer,
            )  # fmt: skip
        )
    return written


def main(argv=None, own_interrupt: bool = True) -> Path:
    """Runs the sweep of ``argv``. ``own_interrupt``: Ctrl-C ends in one line saying how to
    continue (a caller that runs several sweeps, as experiments.paper, passes False and
    says it in its own words)."""
    invocation = parse_args(argv)
    config, saved, writer = start(invocation)
    if not writer:  # another host of a multi-host run: process 0 holds the lock
        return run_sweep(invocation, config, saved, writer)
    try:
        with run_lock(invocation.out, "sweep"):
            return run_sweep(invocation, config, saved, writer)
    except RunLocked as error:
        raise SystemExit(f"cannot run: {error}") from None
    except KeyboardInterrupt:
        if not own_interrupt:
            raise
        out = invocation.out
        if (out / "config.json").exists():
            message = f"finished chunks are kept; --resume {out} continues from the last one"
        else:
            message = "before the run began: nothing was written"
        raise SystemExit(f"\ninterrupted {message}") from None


def already_complete(out: Path) -> bool:
    """Whether ``out``'s summary.json says its run is finished and every output is there (so
    a resume has nothing to do: nothing is recomputed or rewritten)."""
    from pngail_jax.integrity import IntegrityError, read_json

    if not all((out / name).exists() for name in STALE_OUTPUTS):
        return False
    try:
        summary = read_json(out / "summary.json", "run summary")
    except (FileNotFoundError, IntegrityError):
        return False
    return bool(summary.get("complete")) and summary.get("iterations_done") == summary.get(
        "iterations"
    )


STALE_OUTPUTS = ("summary.json", "summary.md", "metrics.csv", "curves.png", "policies")


def drop_stale_outputs(out: Path, iterations_done: int) -> None:
    """Removes outputs that claim more iterations than the checkpoint a resume starts from
    (its newer checkpoints were damaged or deleted): they are written again as the run goes."""
    from pngail_jax.integrity import IntegrityError, read_json

    try:
        claimed = read_json(out / "summary.json", "run summary").get("iterations_done", 0)
    except (FileNotFoundError, IntegrityError):
        return
    if claimed <= iterations_done:
        return
    print(
        f"note: the outputs say {claimed} iterations, the checkpoint holds {iterations_done}: "
        "removing the outputs until the run reaches them again"
    )
    for name in STALE_OUTPUTS:
        path = out / name
        if path.is_dir():
            shutil.rmtree(path)
        else:
            path.unlink(missing_ok=True)


def run_sweep(invocation: Invocation, config: RunConfig, saved, writer: bool) -> Path:
    out = invocation.out
    checkpoint = None
    if saved is not None:  # these checks before the minutes of compiling
        check_inputs(saved, invocation.args.allow_changed_inputs)
        if already_complete(out):
            print(f"{out}: the run is already complete; nothing to do")
            return out
        checkpoint = intact_checkpoint(out / "checkpoints")
    elif writer:  # a new run: the claim again, now that this process holds the lock
        refusal = output_refusal(out, "sweep", invocation.args.overwrite)
        if refusal:
            raise SystemExit(refusal)
    run = build(config, saved)
    if writer and saved is None:  # a resumed run keeps its directory as it is (no marker
        # added to an older run: its missing seal would then read as removed)
        prepare_output(out, "sweep", overwrite=invocation.args.overwrite)
        write_config(out, run, invocation.argv)
    print(f"-> {out}", flush=True)
    state, progress = initial_state(run, checkpoint)
    if writer and saved is not None:
        drop_stale_outputs(out, progress.iterations_done(run.grid))
    logger = None
    if writer and config.log:
        from pngail_jax.tracking import open_logger

        logger = open_logger(out, config.log, config.to_dict(), out.name)
    start_time = time.perf_counter()
    try:
        host_state = run_chunks(run, out, state, progress, writer, logger)
    finally:
        if logger is not None:
            logger.close()
    export_policies(out, run, host_state, progress, writer)
    if not writer:
        return out
    markdown = write_outputs(out, run, progress)
    print()
    print(markdown.split("\n\nFinal return")[0])
    print(
        f"\ndone in {format_seconds(time.perf_counter() - start_time)} (+ compile); wrote "
        f"{out}/{{config.json,metrics.csv,curves.png,summary.md,summary.json,policies/,"
        "checkpoints/}"
    )
    return out


if __name__ == "__main__":
    main()
