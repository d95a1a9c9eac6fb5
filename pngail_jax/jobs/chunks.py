"""The one chunk step every job runs, and what goes with it: progress, checkpoints, resuming
and stopping at a checkpoint.

A job compiles its work into a ``pngail_jax.grid.Grid`` and runs it a chunk at a time:
``run_chunks`` runs the chunk, fetches its metrics, joins them to those so far, times it,
prints the job's progress line and writes a checkpoint (``chunk_NNNN/``: the state via orbax,
the metrics, the init's metrics, the timing, then the digests that mark it complete; the last
two kept). A stop asked for by a signal handler (``stop_after_this_chunk``) waits for the
chunk's checkpoint. ``start`` begins from a checkpoint (``intact_checkpoint``), without running
the grid's init again where the checkpoint keeps the init's metrics, or afresh, saving the
start as ``chunk_0000`` where the job asks (an init that runs long).
"""

from __future__ import annotations

import contextlib
import dataclasses
import shutil
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np

from pngail_jax.analysis.runs import UntrustedRun, sealed_document, sealed_part
from pngail_jax.jobs.errors import RunError
from pngail_jax.storage.checkpoint import restore_tree, save_tree
from pngail_jax.storage.integrity import (
    IntegrityError,
    atomic_path,
    read_json,
    verify_manifest,
    write_json,
    write_manifest,
)
from pngail_jax.storage.outputs import output_owner, record_held_outputs


@dataclasses.dataclass
class Progress:
    """What a run has done: chunks, metrics so far (float[G, I]), the timing of its chunks
    (``seconds``, ``steps``, and ``chunk_seconds``: the cumulative seconds at each chunk's
    end); ``init_metrics``: what the grid's initialisation measured."""

    chunks_done: int
    init_metrics: dict
    metrics: dict | None
    timing: dict
    last_chunk_seconds: float = 0.0

    def iterations_done(self, grid) -> int:
        return self.chunks_done * grid.iterations_per_chunk

    def add(self, chunk_metrics: dict, seconds: float, steps: int) -> None:
        """Joins the next chunk's metrics (float[G, I]) and timing."""
        chunk = self.chunks_done
        self.timing["seconds"] += seconds
        # A run begun by an older version has no chunk ends for its first chunks, and gets
        # none (metrics.csv leaves their wall clock empty).
        self.timing.setdefault("chunk_seconds", [None] * chunk).append(self.timing["seconds"])
        self.timing["steps"] = self.timing.get("steps", 0) + steps
        self.last_chunk_seconds = seconds
        if self.metrics is None:
            self.metrics = chunk_metrics
        else:  # a metric the earlier chunks lack (a run begun by an older version): NaN there
            before = next(iter(self.metrics.values())).shape[:2]
            self.metrics = {
                name: np.concatenate(
                    [self.metrics.get(name, np.full(before, np.nan)), chunk_metrics[name]], axis=1
                )
                for name in chunk_metrics
            }
        self.chunks_done = chunk + 1


def start(grid, checkpoint: Path | None, *, save_to: Path | None = None, writer: bool = True):
    """The grid's first state and progress: restored from ``checkpoint`` (an intact
    ``chunk_*`` directory, ``intact_checkpoint``), else fresh. A checkpoint that keeps its
    grid's initial metrics (``INIT_METRICS``) is restored without running the grid's init; an
    older one runs it again for them. ``save_to``: a fresh start is saved there at once
    (``chunk_0000``), for a job whose init runs long (ILID's discriminators), so a run cut
    before its first chunk ends resumes after its init (every process calls it; ``writer``
    writes)."""
    if checkpoint is not None and (checkpoint / INIT_METRICS).exists():
        progress = Progress(0, _load_metrics(checkpoint / INIT_METRICS), None, _fresh_timing())
        return restore_checkpoint(grid, grid.state_shape(), checkpoint, progress), progress
    state, init_metrics = grid.init()
    progress = Progress(0, grid.fetch(init_metrics), None, _fresh_timing())
    if checkpoint is not None:
        template = jax.eval_shape(lambda: grid.unpad(state))
        state = restore_checkpoint(grid, template, checkpoint, progress)
    elif save_to is not None:
        save_checkpoint(save_to, progress, grid.fetch(state), writer)
    return state, progress


def _fresh_timing() -> dict:
    return {"seconds": 0.0, "steps": 0}


# A checkpoint's files beside its state: the metrics of its chunks so far (none in the
# ``chunk_0000`` of a saved start) and, since 0.2, the grid's initial metrics.
CHUNK_METRICS, INIT_METRICS = "metrics.npz", "init_metrics.npz"


def _save_metrics(path: Path, metrics: dict | None) -> None:
    stored = {name.replace("/", ":"): value for name, value in (metrics or {}).items()}
    with atomic_path(path) as temporary:
        np.savez(temporary, **stored)


def _load_metrics(path: Path) -> dict | None:
    """The metrics ``_save_metrics`` wrote (None where it wrote none)."""
    with np.load(path) as stored:
        metrics = {name.replace(":", "/"): stored[name] for name in stored.files}
    return metrics or None


def run_chunks(
    grid,
    state,
    progress: Progress,
    num_chunks: int,
    *,
    steps_per_chunk: int,
    line: Callable[[Progress, dict], str],
    checkpoints: Path | None = None,
    writer: bool = True,
    after: Callable | None = None,
):
    """Runs the chunks after ``progress.chunks_done`` up to ``num_chunks``, each by the one
    chunk step: run, fetch, join the metrics, time (``steps_per_chunk`` environment steps),
    print ``line(progress, chunk_metrics)``, checkpoint into ``checkpoints`` (when given;
    every process takes part, ``writer`` writes) and call ``after(state, host_state,
    chunk_metrics)``, then bring the list of files of the run ``checkpoints`` lies in up to
    date (``outputs.record_held_outputs``). A chunk expected to run long gets a line when it
    starts. A stop asked for meanwhile (``stop_after_this_chunk``) raises ``KeyboardInterrupt``
    once the chunk's checkpoint is written. Returns the state and the last host copy of it
    (None without checkpoints)."""
    host_state = None
    while progress.chunks_done < num_chunks:
        notice = long_chunk_notice(progress, num_chunks, grid.iterations_per_chunk)
        if notice:
            print(notice, flush=True)
        with finishing_chunk():
            chunk_start = time.perf_counter()
            state, chunk_metrics = grid.run_chunk(state)
            chunk_metrics = grid.fetch(chunk_metrics)
            progress.add(chunk_metrics, time.perf_counter() - chunk_start, steps_per_chunk)
            print(line(progress, chunk_metrics), flush=True)
            if checkpoints is not None:  # every process takes part in the gather and the save
                host_state = grid.fetch(state)
                save_checkpoint(checkpoints, progress, host_state, writer)
            if after is not None:
                after(state, host_state, chunk_metrics)
            record_held_outputs(checkpoints)  # a run killed later lists what it wrote so far
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


def long_chunk_notice(progress: Progress, num_chunks: int, per_chunk: int):
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


def nanmean(values, axis=None):
    """Mean ignoring NaN (iterations where no training episode finished), NaN if all are."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(values, axis=axis)


def blocks_per_chunk(num_evaluations: int, target_blocks: int) -> int:
    """The largest divisor of num_evaluations not above the target (so all chunks match)."""
    return max(
        d for d in range(1, min(target_blocks, num_evaluations) + 1) if not num_evaluations % d
    )


def intact_checkpoint(directory: Path) -> Path | None:
    """The newest ``chunk_*`` checkpoint in ``directory`` whose files match their digests,
    saying which newer ones are damaged or incomplete and left aside; None if there is none."""
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


def save_checkpoint(directory: Path, progress: Progress, host_state, writer: bool):
    """Writes chunk_NNNN/ (state via orbax, metrics, progress, then the digests that mark it
    complete) and keeps the last two, so a damaged newest one leaves an older one to resume.

    Every process calls it (orbax synchronises processes); only the writer writes the rest.
    """
    path = directory / f"chunk_{progress.chunks_done:04d}"
    try:
        save_tree(path / "state", host_state)
        if not writer:
            return
        _save_metrics(path / CHUNK_METRICS, progress.metrics)
        _save_metrics(path / INIT_METRICS, progress.init_metrics)
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


def restore_checkpoint(grid, template, checkpoint: Path, progress: Progress):
    """The grid's state saved in ``checkpoint`` (an intact ``chunk_*``; ``template``, the
    shapes of its real cells' state, ``Grid.state_shape``, gives the structure), with
    ``progress`` set to its metrics, chunks done and timing."""
    try:
        state = grid.place(restore_tree(checkpoint / "state", template))
    except ValueError as error:  # intact, but of another grid
        raise RunError(f"cannot resume from {checkpoint}: {error}") from None
    progress.metrics = _load_metrics(checkpoint / CHUNK_METRICS)
    done = read_json(checkpoint / "progress.json", "progress record")
    progress.chunks_done, progress.timing = done["chunks_done"], done["timing"]
    print(f"resumed from {checkpoint} (iteration {progress.iterations_done(grid)})")
    return state


def resumable_config(out: Path, program: str, finished: str, *, part=sealed_part) -> dict:
    """The config.json of ``program``'s interrupted run in ``out``, which a resume compares
    with its own config; ``RunError`` with one line for a directory holding no run of
    ``program``, a finished run (its ``finished`` file written), or a config.json without
    its seal or changed since the run began (``part``: what the seal covers)."""
    if output_owner(out) != program:
        raise RunError(f"--resume {out} holds no run of experiments.{program}")
    if (out / finished).exists():
        raise RunError(f"--resume {out}: the run is complete (its {finished} is written)")
    try:
        saved, _ = sealed_document(
            out, f"--resume {out}", what=f"{program} run config", part=part,
            unsealed_remedy="start a new run",
        )  # fmt: skip
    except UntrustedRun as error:
        raise RunError(str(error)) from None
    return saved
