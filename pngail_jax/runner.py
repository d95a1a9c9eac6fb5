"""The run lifecycle: ``run(config, out)`` trains a ``RunConfig``'s grid and writes its outputs.

    from pngail_jax import RunConfig, run

    result = run(RunConfig.preset("check", demos="data/released/Pendulum-v1_mixture.npy"),
                 "runs/first")
    result.table()          # per method: final return, mean, s.e., IQM and its 95% interval
    result.files["curves"]  # runs/first/curves.png

One call holds what ``python -m experiments.sweep`` does after reading its flags: the output
contract (a new or empty directory, or its own run with ``overwrite``; ``pngail_jax.outputs``),
the run lock, building the environment, demonstrations, trainer and compiled ``Grid``, the
chunk loop with progress lines, a checkpoint after every chunk, partial and final outputs
(``config.json`` with its seal, ``metrics.csv``, ``curves.png``, ``summary.md``,
``summary.json``, ``policies/``) and ``resume=True``, which continues from the last intact
checkpoint to the numbers of an uninterrupted run after checking the saved config and input
files. A refusal is a ``RunError`` whose message is one line; the program prints it.

Process set-up stays with the caller, because it must come before JAX starts its backend:
XLA CPU devices (``RunConfig.cpu_devices``, ``configure_devices``), the compilation cache and
``jax.distributed`` for multi-host runs (every process calls ``run``; process 0 writes).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import shutil
import time
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pngail_jax import settings as run_settings
from pngail_jax.outputs import MARKER, RunLocked, output_refusal, prepare_output, run_lock
from pngail_jax.run_config import RunConfig, upgrade_saved_config
from pngail_jax.tracking import ticking
from pngail_jax.validation import ConfigError

if TYPE_CHECKING:
    from pngail_jax.rl import TRPOTrainer

DEMO_CACHE = Path("runs") / "demos-cache"
MINARI_PREFIX = "minari:"
PROGRAM = "sweep"  # the owner its directories are marked with (pngail_jax.outputs)


class RunError(Exception):
    """A run refused or stopped, for a reason its one-line message names (no traceback
    needed: a bad input, a changed file, a full disk)."""


# -- a resumed run's config and inputs ---------------------------------------


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
        raise RunError(f"--resume {directory}: {error}") from None
    if changes is None:
        if (directory / MARKER).exists():  # made by a version that seals: the seal was removed
            raise RunError(
                f"--resume {directory}: its seal {SEAL} is missing, so config.json cannot be "
                "checked; restore it, or start a new run"
            )
        print(f"note: {directory}/config.json has no seal (an older version made the run)")
    elif changes:
        raise RunError(
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
        raise RunError(f"--resume {directory}: no config.json there")
    try:
        raw = read_json(path, "run config")
    except IntegrityError as error:
        raise RunError(f"--resume {directory}: {error}") from None
    if isinstance(raw, dict):
        check_seal(directory, raw)
    try:
        data = upgrade_saved_config(raw)
        _register_recorded_methods(data)
        try:
            config = RunConfig.from_dict(data)
        except ConfigError as error:
            if error.field != "methods":
                raise
            raise RunError(
                f"--resume {directory}: {error} (a name given to pngail_jax.methods.register "
                "must be registered again before the run resumes)"
            ) from None
        _check_methods_unchanged(directory, data["resolved"].get("methods"))
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
        raise RunError(f"--resume {directory}: {error}") from None
    except (TypeError, ValueError, KeyError, AttributeError) as error:
        raise RunError(
            f"--resume {directory}: {path} is damaged or not a run config ({error!r})"
        ) from None


def _register_recorded_methods(data: dict) -> None:
    """Registers again, from the run's record, each method it names that was given to
    ``methods.register`` in the process that began it (a ``package.module:preset`` is imported
    again instead, and checked against its record by ``_check_methods_unchanged``)."""
    from pngail_jax import methods

    recorded = data["resolved"].get("methods") or {}
    for name in data.get("methods", ()):
        if isinstance(name, str) and name not in methods.PRESETS and ":" not in name:
            if name in recorded:
                methods.register_recorded(name, recorded[name])
                print(f"note: method {name!r} registered again from the run's config.json")


def _check_methods_unchanged(directory: Path, recorded: dict | None) -> None:
    """Refuses to resume a run whose methods now resolve to other presets than it began
    with (an edited ``package.module:preset``); runs from before the record pass."""
    from pngail_jax.methods import preset_record

    for name, record in (recorded or {}).items():
        now = json.loads(json.dumps(preset_record(name)))
        if now != record:
            raise RunError(
                f"--resume {directory}: method {name!r} is not the preset the run began with "
                f"(then {record}, now {now}); restore it, or start a new run"
            )


def check_inputs(saved: SavedRun, allow_changed: bool) -> None:
    """Refuses to resume on input files that differ from those the run began with."""
    from pngail_jax.integrity import changed_inputs

    changes = changed_inputs(saved.inputs)
    if not changes:
        return
    listing = "; ".join(changes)
    if not allow_changed:
        raise RunError(
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


# -- building the grid ----------------------------------------------------------------------


@dataclasses.dataclass
class BuiltRun:
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
    """The demonstrations and the path they came from: ``config.demos`` (a file of rows that
    is not an authors' one is split by ``env``'s sizes), else made once with
    ``pngail_jax.demos.make`` (its defaults: 1:4 optimal to intermediate trajectories) and
    reused from ``DEMO_CACHE/<env>/``."""
    from pngail_jax.demos import DemonstrationError, load_demonstrations

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
    cached = DEMO_CACHE / config.env / "demos.npz"
    if cached.exists():
        try:
            demos = load_demonstrations(cached)
            print(f"reusing demonstrations {cached}", flush=True)
            return demos, str(cached.absolute())
        except DemonstrationError as error:
            print(f"the cached demonstrations are damaged: {error}; making them again")
    else:
        print(f"no demonstrations given: making them into {cached.parent}")
    from pngail_jax.demos import make

    # The cache is the runner's own: a making cut short there is replaced.
    make.make_demonstrations(
        make.MakeDemosConfig(env=config.env), cached.parent, overwrite=cached.parent.exists()
    )
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
        raise RunError(
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


def _check_split_sizes(label_ratios, num_demos: int) -> None:
    """RunError unless every label ratio leaves a labelled and an unlabelled row."""
    for ratio in label_ratios:
        num_labelled = round(ratio * num_demos)
        if not 0 < num_labelled < num_demos:
            raise RunError(
                f"--label-ratio {ratio} labels {num_labelled} of {num_demos} rows; "
                "need at least one labelled and one unlabelled row"
            )


def build(config: RunConfig, saved: SavedRun | None) -> BuiltRun:
    """Environment, demonstrations, trainer and the compiled grid of ``config`` (a resumed
    run's demonstrations from the path it began with)."""
    import jax

    from pngail_jax.adversarial import AdversarialTrainer
    from pngail_jax.demos import DemonstrationError
    from pngail_jax.grid import Grid, make_cells, stack_cells

    try:
        env = run_settings.make_env(config.env, config.settings)
    except ValueError as error:  # e.g. a custom factory that raised or returned no Env
        raise RunError(f"environment: {error}") from None
    try:
        demos, demos_path = load_or_make_demos(config, saved.demos_path if saved else None, env)
    except (DemonstrationError, FileNotFoundError, ImportError) as error:
        raise RunError(f"demonstrations: {error}") from None
    try:
        trainer = AdversarialTrainer(config.adversarial_config(demos.num_rows), env, demos)
        trainer.check_methods(config.methods)
        trainer.check_label_ratios(config.label_ratios)
    except DemonstrationError as error:
        raise RunError(f"{demos_path}: {error}") from None
    _check_split_sizes(config.label_ratios, trainer.num_demos)
    cells = make_cells(
        config.methods, config.seeds, config.label_ratios, config.noise_stds, config.grid_axes
    )
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
    return BuiltRun(
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


def write_config(out: Path, run: BuiltRun, command: Sequence[str] | None = None) -> None:
    """config.json: the RunConfig, what it resolved to (with the SHA-256 of every input file,
    which ``--resume`` checks), and provenance."""
    from pngail_jax.integrity import seal, write_json
    from pngail_jax.methods import preset_record
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
            # What each method name resolved to: a resume refuses a changed preset.
            "methods": {name: preset_record(name) for name in run.config.methods},
            "inputs": input_files(run.config, run.demos_path),
        },
        "provenance": {
            **provenance(),
            **({} if command is None else {"command_line": list(command)}),
        },
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


def initial_state(run: BuiltRun, checkpoint: Path | None):
    """The grid's state and progress: from ``checkpoint`` (an intact ``chunk_*`` directory,
    ``intact_checkpoint``) when resuming, else fresh."""
    grid = run.grid
    start = time.perf_counter()
    state, init_metrics = grid.init()
    progress = Progress(0, grid.fetch(init_metrics), None, {"seconds": 0.0, "steps": 0})
    if checkpoint is not None:
        return restore_checkpoint(grid, state, checkpoint, progress), progress
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


def run_chunks(run: BuiltRun, out: Path, state, progress: Progress, writer: bool, logger=None):
    """Runs the remaining chunks: progress lines, a checkpoint and partial outputs after each."""
    num_chunks = run.config.iterations // run.grid.iterations_per_chunk
    reported_bad: set[int] = set()
    host_state = None
    while progress.chunks_done < num_chunks:
        notice = _long_chunk_notice(progress, num_chunks, run.grid.iterations_per_chunk)
        if notice:
            print(notice, flush=True)
        with finishing_chunk():  # a stop asked for meanwhile waits for its checkpoint
            state, host_state = _run_chunk(run, out, state, progress, writer, logger, reported_bad)
    return run.grid.fetch(state) if host_state is None else host_state


def _run_chunk(run: BuiltRun, out: Path, state, progress: Progress, writer, logger, reported_bad):
    """The next chunk, its progress line, checkpoint and partial outputs; ``reported_bad``
    (the cells already reported diverged) grows. Returns the device and the host state."""
    from pngail_jax.grid import nonfinite_cells

    grid, config = run.grid, run.config
    num_chunks, chunk = config.iterations // grid.iterations_per_chunk, progress.chunks_done
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
    return state, host_state


# -- stopping at a checkpoint: a program's signal handler (Ctrl-C, SIGTERM) asks, and a chunk
# that has begun ends, is saved, and then stops the run (a signal reaches Python only once the
# compiled chunk returns, so raising at once would discard a finished chunk).
_STOP = {"inside": False, "requested": False}


def stop_after_this_chunk() -> bool:
    """For a signal handler: inside a chunk (``finishing_chunk``) records the request and
    returns True, and the run stops once the chunk's checkpoint is written; otherwise, or on
    a second request, False: the handler stops the program at once."""
    if not _STOP["inside"] or _STOP["requested"]:
        return False
    _STOP["requested"] = True
    return True


@contextlib.contextmanager
def finishing_chunk():
    """A chunk, its checkpoint and its partial outputs; a stop asked for within raises
    ``KeyboardInterrupt`` when they are done."""
    _STOP.update(inside=True, requested=False)
    try:
        yield
    finally:
        requested = _STOP["requested"]
        _STOP.update(inside=False, requested=False)
    if requested:
        raise KeyboardInterrupt("stopped at a checkpoint")


# A chunk expected to run this long gets a line when it starts (its progress line comes only
# when it ends): f-IRL's chunk of 100 iterations runs an hour on a 2-core CPU.
LONG_CHUNK_SECONDS = 120.0


def _long_chunk_notice(progress: Progress, num_chunks: int, per_chunk: int):
    """A line saying when the next chunk (after ``progress.chunks_done``) should end, at the
    pace of the chunks before it (None for a short chunk, or for the first, whose pace is not
    known yet)."""
    chunk = progress.chunks_done
    if chunk == 0 or progress.timing["seconds"] <= 0:
        return None
    expected = progress.timing["seconds"] / chunk
    if expected < LONG_CHUNK_SECONDS:
        return None
    first, last = chunk * per_chunk + 1, (chunk + 1) * per_chunk
    end = time.strftime("%H:%M", time.localtime(time.time() + expected))
    return (
        f"  chunk {chunk + 1}/{num_chunks} (iterations {first}-{last}) started; at the pace "
        f"so far ({format_seconds(expected)} a chunk) it ends about {end}"
    )


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
        raise RunError(
            f"cannot write checkpoint {path}: {error.strerror or error}; the chunks before it "
            f"are kept: free space (or fix the disk), then --resume {directory.parent}"
        ) from None
    for old in sorted(directory.glob("chunk_*"))[:-2]:
        shutil.rmtree(old)


# -- outputs ----------------------------------------------------------------------------------


def _title(config: RunConfig, num_cells: int) -> str:
    return f"{config.env}: {num_cells} runs, {config.iterations} iterations"


def write_outputs(out: Path, run: BuiltRun, progress: Progress) -> str:
    """metrics.csv, curves.png, diagnostics.png, summary.json and summary.md of the iterations
    done so far
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
    report.plot_diagnostics(out / "diagnostics.png", cells, metrics, title, diverged)
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
            baseline=config.baseline,
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


def export_policies(out: Path, run: BuiltRun, host_state, progress: Progress, writer: bool):
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


STALE_OUTPUTS = (
    "summary.json",
    "summary.md",
    "metrics.csv",
    "curves.png",
    "diagnostics.png",
    "policies",
)


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


def configure_devices(requested: int | None) -> None:
    """Splits the CPU into ``requested`` XLA devices (before JAX starts its backend).

    Not by default: benchmarks/grid_throughput.py measured a 35-cell grid on 2 cores at
    89.9k steps/s on one device and 90.9k on two (one XLA CPU device already uses every core).
    """
    import jax

    if requested is not None and requested > 1:
        jax.config.update("jax_num_cpu_devices", requested)


# -- the run ----------------------------------------------------------------------------------

OUTPUT_FILES = {
    "config": "config.json",
    "metrics": "metrics.csv",
    "curves": "curves.png",
    "diagnostics": "diagnostics.png",
    "summary_md": "summary.md",
    "summary": "summary.json",
    "policies": "policies",
    "checkpoints": "checkpoints",
}


@dataclasses.dataclass(frozen=True)
class RunResult:
    """A finished run: where it wrote, its summary (``summary.json``'s content) and its
    ``summary.md`` text; ``files`` maps each output to its path."""

    out: Path
    summary: dict
    markdown: str

    @property
    def files(self) -> dict[str, Path]:
        return {name: self.out / file for name, file in OUTPUT_FILES.items()}

    def table(self, metric: str = "final_return") -> list[dict]:
        """One row per method (and setting) of ``metric`` across seeds: ``final_return``,
        ``average_return`` (all of training), ``late_average_return`` (its last 10%), or
        their ``*_normalized_return`` forms. Each row: ``group``, ``mean``, ``se`` (standard
        error), ``iqm`` and ``ci95`` (its 95% bootstrap interval), ``seeds``."""
        rows = []
        for group, row in self.summary["methods"].items():
            if f"{metric}_mean" not in row:
                known = sorted(k.removesuffix("_mean") for k in row if k.endswith("_mean"))
                raise KeyError(f"no metric {metric!r} in the summary; it has {known}")
            rows.append(
                {
                    "group": group,
                    **{part: row[f"{metric}_{part}"] for part in ("mean", "se", "iqm", "ci95")},
                    "seeds": row.get("num_seeds"),
                }
            )
        return rows


def run(
    config: RunConfig | None,
    out: str | os.PathLike,
    *,
    resume: bool = False,
    overwrite: bool = False,
    allow_changed_inputs: bool = False,
    command: Sequence[str] | None = None,
    saved: SavedRun | None = None,
) -> RunResult | None:
    """Trains ``config``'s grid into ``out`` and returns its result (None in a process of a
    multi-host run other than process 0, which writes).

    ``resume``: continue the run in ``out`` from its last intact checkpoint, with the config
    its ``config.json`` holds (``config`` must then be None or that same config; ``saved``
    passes it when the caller has read it already, with ``load_saved``). ``overwrite``:
    replace a finished or unfinished run of the sweep in ``out``. ``allow_changed_inputs``:
    resume although a demonstration file changed since the run began (``config.demos`` None:
    they are made once and cached, ``load_or_make_demos``). ``command``: the command
    line recorded in ``config.json`` (default: this process's).
    Raises ``RunError`` naming the problem (before any computation where it can be seen then).
    """
    import jax

    out = Path(out)
    if resume:
        saved = saved or load_saved(out)
        if config is not None and _comparable(_as_saved(config, saved)) != _comparable(
            saved.config
        ):
            raise RunError(
                f"resume {out}: the config given differs from the run's config.json; pass None "
                "to continue the run as it began"
            )
        config = saved.config
        if saved.device_count != len(jax.devices()):
            print(
                f"WARNING: resuming on {len(jax.devices())} devices, the run began on "
                f"{saved.device_count}: a different sharding can change the last bits, and "
                "the rest of the run with them"
            )
    elif config is None:
        raise RunError("run: give a RunConfig (or resume=True to continue the run in out)")
    else:
        config = _absolute_paths(config)
    _warn_on_devices(config)
    writer = jax.process_index() == 0
    if not writer:  # another host of a multi-host run: process 0 holds the lock
        return _run_locked(config, out, saved, writer, overwrite, allow_changed_inputs,
                           command)  # fmt: skip
    try:
        with run_lock(out, PROGRAM):
            return _run_locked(config, out, saved, writer, overwrite, allow_changed_inputs,
                               command)  # fmt: skip
    except RunLocked as error:
        raise RunError(f"cannot run: {error}") from None


def _as_saved(config: RunConfig, saved: SavedRun) -> RunConfig:
    """``config`` as its run's config.json holds it: absolute paths, and the physics engine
    that ran when the config left it to the platform."""
    config = _absolute_paths(config)
    physics = saved.config.settings.physics
    if config.settings.physics is None and physics is not None:
        config = config.replace(settings=config.settings.replace(physics=physics))
    return config


def _comparable(config: RunConfig) -> dict:
    """``config.to_dict()`` with its file paths normalised (``a/../b`` is ``b``)."""
    document = config.to_dict()
    for name in ("demos", "conf"):
        if document.get(name) and not str(document[name]).startswith(MINARI_PREFIX):
            document[name] = os.path.normpath(document[name])
    return document


def _warn_on_devices(config: RunConfig) -> None:
    """``cpu_devices`` only takes effect before JAX starts (``configure_devices``, which the
    sweep calls): say so when this process has another count than the config asks for."""
    import jax

    wanted = config.cpu_devices
    if wanted and jax.devices()[0].platform == "cpu" and wanted != jax.local_device_count():
        print(
            f"WARNING: the config asks for {wanted} CPU devices and this process has "
            f"{jax.local_device_count()}: call pngail_jax.runner.configure_devices({wanted}) "
            "before anything runs on JAX, or set cpu_devices=None"
        )


def _absolute_paths(config: RunConfig) -> RunConfig:
    """``config`` with its demonstration and confidence files as absolute paths, so that a
    resume from another working directory reads the same files."""
    paths = {}
    if config.demos is not None and not config.demos.startswith(MINARI_PREFIX):
        paths["demos"] = str(Path(config.demos).absolute())
    if config.conf is not None:
        paths["conf"] = str(Path(config.conf).absolute())
    return config.replace(**paths) if paths else config


def _run_locked(
    config, out, saved, writer, overwrite, allow_changed_inputs, command
) -> RunResult | None:
    checkpoint = None
    if saved is not None:  # these checks before the minutes of compiling
        check_inputs(saved, allow_changed_inputs)
        if already_complete(out):
            print(f"{out}: the run is already complete; nothing to do")
            return _result(out) if writer else None
        checkpoint = intact_checkpoint(out / "checkpoints")
    elif writer:  # a new run: the claim (again, for a program), now that the lock is held
        refusal = output_refusal(out, PROGRAM, overwrite)
        if refusal:
            raise RunError(refusal)
    built = build(config, saved)
    if writer and saved is None:  # a resumed run keeps its directory as it is (no marker
        # added to an older run: its missing seal would then read as removed)
        prepare_output(out, PROGRAM, overwrite=overwrite)
        write_config(out, built, command)
    print(f"-> {out}", flush=True)
    state, progress = initial_state(built, checkpoint)
    if writer and saved is not None:
        drop_stale_outputs(out, progress.iterations_done(built.grid))
    start_time = time.perf_counter()
    host_state = _run_logged(built, out, state, progress, writer)
    export_policies(out, built, host_state, progress, writer)
    if not writer:
        return None
    markdown = write_outputs(out, built, progress)
    print()
    print(markdown.split("\n\nFinal return")[0])
    print(
        f"\ndone in {format_seconds(time.perf_counter() - start_time)} (+ compile); wrote "
        f"{out}/{{config.json,metrics.csv,curves.png,diagnostics.png,summary.md,summary.json,"
        "policies/,checkpoints/}"
    )
    return _result(out)


def _run_logged(built: BuiltRun, out: Path, state, progress: Progress, writer: bool):
    """``run_chunks`` with the config's tracking backends open (process 0 only)."""
    logger = None
    if writer and built.config.log:
        from pngail_jax.tracking import open_logger

        logger = open_logger(out, built.config.log, built.config.to_dict(), out.name)
    try:
        return run_chunks(built, out, state, progress, writer, logger)
    finally:
        if logger is not None:
            logger.close()


def _result(out: Path) -> RunResult:
    from pngail_jax.integrity import read_json

    summary = read_json(out / OUTPUT_FILES["summary"], "run summary")
    return RunResult(out, summary, (out / OUTPUT_FILES["summary_md"]).read_text())


# -- a TRPO run of stacked seeds (train_rl, make_demos) ------------------------------------


def nanmean(values, axis=None):
    """Mean ignoring NaN (iterations where no training episode finished), NaN if all are."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(values, axis=axis)


def train_seeds(
    trainer: TRPOTrainer, hyperparams, keys, on_block=None, checkpoints: Path | None = None
):
    """Runs ``trainer`` for stacked seeds, one compiled block of ``eval_every`` iterations at a
    time (``pngail_jax.grid.Grid``), printing progress after each.

    Calls ``on_block(iteration, trpo_state, block_metrics)`` if given (e.g. to keep
    checkpoints). With ``checkpoints`` (a directory), the whole state is saved there after
    every block (``chunk_NNNN/``, the last two kept), and a run that finds an intact one
    continues from it to the numbers of an uninterrupted run. The numbers are those of the
    whole-scan ``trainer.train``. Returns ``(final TRPOState, metrics)`` with metrics
    float[seeds, num_iterations].
    """
    config = trainer.config
    from pngail_jax.grid import Grid

    grid = Grid(trainer, (hyperparams, keys), blocks_per_chunk=1)
    print(f"compiled in {grid.compile_seconds:.1f} s", flush=True)
    state, progress = _seeds_start(grid, checkpoints)
    for done_blocks in range(progress.chunks_done + 1, config.num_evaluations + 1):
        block_start = time.perf_counter()
        state, metrics = grid.run_chunk(state)
        metrics = grid.fetch(metrics)
        progress.metrics = (
            metrics
            if progress.metrics is None
            else {
                name: np.concatenate([progress.metrics[name], metrics[name]], 1) for name in metrics
            }
        )
        progress.chunks_done = done_blocks
        seconds = time.perf_counter() - block_start
        progress.timing["seconds"] += seconds
        rate = grid.num_cells * config.eval_every * config.batch_size / seconds
        print(
            f"iter {done_blocks * config.eval_every:5d}  "
            f"eval {np.mean(metrics['eval/return'][:, -1]):9.1f} "
            f"[{', '.join(f'{r:.0f}' for r in metrics['eval/return'][:, -1])}]  "
            f"train {nanmean(metrics['train/episode_return'][:, -1]):9.1f}  "
            f"{rate:10,.0f} steps/s",
            flush=True,
        )
        if on_block is not None:
            host_state = grid.fetch(trainer.policy_state(state))
            on_block(done_blocks * config.eval_every, host_state, metrics)
        if checkpoints is not None:
            _save_checkpoint(checkpoints, progress, grid.fetch(state), writer=True)
    return grid.fetch(trainer.policy_state(state)), progress.metrics


def _seeds_start(grid, checkpoints: Path | None):
    """A seeds run's first state and progress: from the newest intact checkpoint in
    ``checkpoints`` when there is one, else fresh."""
    state, _ = grid.init()
    progress = Progress(0, {}, None, {"seconds": 0.0})
    found = None
    if checkpoints is not None and checkpoints.exists():
        found = intact_checkpoint(checkpoints)
    if found is None:
        return state, progress
    return restore_checkpoint(grid, state, found, progress), progress


def restore_checkpoint(grid, state, checkpoint: Path, progress: Progress):
    """The grid's state saved in ``checkpoint`` (an intact ``chunk_*``; ``state`` gives the
    structure), with ``progress`` set to its metrics, chunks done and timing."""
    import jax

    from pngail_jax.checkpoint import restore_tree
    from pngail_jax.integrity import read_json

    template = jax.eval_shape(lambda: grid.unpad(state))
    try:
        state = grid.place(restore_tree(checkpoint / "state", template))
    except ValueError as error:  # intact, but of another grid
        raise RunError(f"cannot resume from {checkpoint}: {error}") from None
    with np.load(checkpoint / "metrics.npz") as stored:
        progress.metrics = {name.replace(":", "/"): stored[name] for name in stored.files}
    done = read_json(checkpoint / "progress.json", "progress record")
    progress.chunks_done, progress.timing = done["chunks_done"], done["timing"]
    print(f"resumed from {checkpoint} (iteration {progress.iterations_done(grid)})")
    return state
