"""Feedback on long work: optional experiment tracking (TensorBoard, Weights & Biases) and
``ticking``, the elapsed time of a step that prints nothing itself.

Off by default: ``open_logger(directory, [], ...)`` is ``None``. After each chunk the sweep
calls ``RunLogger.log_chunk(cells, metrics, first_iteration)`` with the chunk's host metrics
(float[G, I]: G cells, I iterations). For every group (the method, plus its setting when the
grid has several, as in ``pngail_jax.analysis.report``) and metric it logs the mean over the group's
seeds of the finite values at each iteration, as ``"{metric}/{group}"`` at step = the 1-based
iteration number; ``"eval/return"`` is also logged per seed as ``"eval/return/{group}/seed{k}"``.
Points where every seed is NaN (``eval/return`` between evaluations) are not logged.

Tags keep only TensorBoard's tag characters (letters, digits, ``_ - .``): a group with a
setting reads ``gail_label_ratio_0.2_noise_0``, the same in both backends.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import re
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from pngail_jax.analysis.report import group_cells
from pngail_jax.config.output import BACKEND_MODULES, LOG_BACKENDS

# Each backend and the module it needs: the config's output part (plain data).
BACKENDS = LOG_BACKENDS
PER_SEED_METRICS = ("eval/return",)
WANDB_PROJECT = "pngail-jax"

Scalars = dict[int, dict[str, float]]
"""Step -> {tag: value}, what one chunk writes."""


def _tag_part(label: str) -> str:
    return re.sub(r"[^-\w.]+", "_", label).strip("_")


def chunk_scalars(
    cells: Sequence, metrics: Mapping[str, np.ndarray], first_iteration: int
) -> Scalars:
    """The scalars of one chunk, by step.

    ``cells``: the G ``pngail_jax.grid.Cell``s; ``metrics``: name -> float[G, I];
    ``first_iteration``: the 1-based iteration number of column 0, so column ``j`` is logged at
    step ``first_iteration + j``. Non-finite values are left out of every mean.
    """
    groups = {_tag_part(label): rows for label, rows in group_cells(cells)[1].items()}
    scalars: Scalars = {}

    def add(tag: str, values: np.ndarray) -> None:
        """``values``: float[S, I]; logs the finite mean of each column that has one."""
        finite = np.isfinite(values)
        counts = finite.sum(axis=0)
        sums = np.where(finite, values, 0.0).sum(axis=0)
        for column in np.flatnonzero(counts):
            step = first_iteration + int(column)
            scalars.setdefault(step, {})[tag] = float(sums[column] / counts[column])

    for name, array in metrics.items():
        array = np.asarray(array, np.float64)
        if array.shape[0] != len(cells):
            raise ValueError(f"metric {name!r} has {array.shape[0]} rows for {len(cells)} cells")
        for group, rows in groups.items():
            add(f"{name}/{group}", array[rows])
            if name in PER_SEED_METRICS:
                for row in rows:
                    add(f"{name}/{group}/seed{cells[row].seed}", array[row : row + 1])
    return dict(sorted(scalars.items()))


class _TensorBoard:
    """Synchronous event-file writer. ``tensorboardX.SummaryWriter`` queues events on a thread
    and its ``flush()`` does not wait for that queue, so a chunk could stay off disk for up to
    ``flush_secs``; writing events directly makes ``flush()`` mean what it says."""

    def __init__(self, directory: Path, config: dict):
        from tensorboardX.event_file_writer import EventsWriter
        from tensorboardX.summary import text

        directory.mkdir(parents=True, exist_ok=True)
        self._events = EventsWriter(str(directory / "events"))
        config_json = json.dumps(config, indent=2, sort_keys=True, default=str)
        self._write(0, text("config", f"```\n{config_json}\n```"))
        self._events.flush()

    def _write(self, step: int, summary) -> None:
        from tensorboardX.proto.event_pb2 import Event

        self._events.write_event(Event(wall_time=time.time(), step=step, summary=summary))

    def write(self, scalars: Scalars) -> None:
        from tensorboardX.proto.summary_pb2 import Summary

        for step, values in scalars.items():
            summary_values = [Summary.Value(tag=t, simple_value=v) for t, v in values.items()]
            self._write(step, Summary(value=summary_values))
        self._events.flush()

    def close(self) -> None:
        self._events.close()


class _Wandb:
    def __init__(self, directory: Path, config: dict, run_name: str):
        import wandb  # checked importable by open_logger

        directory.mkdir(parents=True, exist_ok=True)
        self._run = wandb.init(
            project=WANDB_PROJECT, name=run_name, config=config, dir=str(directory)
        )

    def write(self, scalars: Scalars) -> None:
        for step, values in scalars.items():
            self._run.log(values, step=step)

    def close(self) -> None:
        self._run.finish()


class RunLogger:
    """Scalars of a sweep sent to one or more backends; a context manager that closes them."""

    def __init__(self, writers: Sequence[_TensorBoard | _Wandb]):
        self._writers = list(writers)

    def log_chunk(
        self, cells: Sequence, metrics: Mapping[str, np.ndarray], first_iteration: int
    ) -> None:
        """Logs one chunk (see ``chunk_scalars``) and flushes it to every backend."""
        scalars = chunk_scalars(cells, metrics, first_iteration)
        for writer in self._writers:
            writer.write(scalars)

    def close(self) -> None:
        """Closes every backend; later calls do nothing."""
        writers, self._writers = self._writers, []
        for writer in writers:
            writer.close()

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()


def check_backends(backends: Sequence[str]) -> None:
    """Raises ValueError naming unknown backends and ImportError naming a backend whose module
    is not installed (before anything is opened or written)."""
    unknown = [name for name in backends if name not in BACKENDS]
    if unknown:
        raise ValueError(f"unknown tracking backend(s) {unknown}; choose from {list(BACKENDS)}")
    for name in backends:
        module = BACKEND_MODULES[name]
        # A module already imported (or blocked with None) is decided by sys.modules.
        installed = (
            sys.modules[module] is not None
            if module in sys.modules
            else importlib.util.find_spec(module) is not None
        )
        if not installed:
            raise ImportError(f"the {name!r} tracking backend needs {module}: pip install {module}")


def open_logger(
    directory: str | Path, backends: Sequence[str], config: dict, run_name: str
) -> RunLogger | None:
    """A ``RunLogger`` over ``backends`` (each one of ``BACKENDS``), or ``None`` for none.

    TensorBoard event files go to ``directory/tensorboard/``; a wandb run (project
    ``"pngail-jax"``, named ``run_name``) keeps its local files under ``directory``. ``config``
    (JSON-serialisable) is the wandb run config and a TensorBoard text summary.
    """
    check_backends(backends)
    if not backends:
        return None
    directory = Path(directory)
    writers: list[_TensorBoard | _Wandb] = []
    try:
        for name in dict.fromkeys(backends):
            if name == "tensorboard":
                writers.append(_TensorBoard(directory / "tensorboard", config))
            else:
                writers.append(_Wandb(directory, config, run_name))
    except BaseException:
        RunLogger(writers).close()  # the backends opened before the failure
        raise
    return RunLogger(writers)


class StepCounter:
    """The steps a compiled program has done, as it tells them from inside (a host callback,
    ``offline.ilid.IlidSelection.progress``); a report may come once for each cell or device
    of a grid, so the largest is kept."""

    def __init__(self):
        self.done = 0

    def __call__(self, done) -> None:
        self.done = max(self.done, int(done))


@contextlib.contextmanager
def ticking(label: str, every: float | None = None, stream=None, counter=None, total=None):
    """Shows the elapsed time of a long step that prints nothing itself (a first compile takes
    minutes on a CPU): on a terminal, ``label ... 42 s`` rewritten in place each second;
    elsewhere (a log file), a line every ``every`` seconds (default 30). With a ``counter``
    (``StepCounter``) of ``total`` steps, the steps done and the time left at that pace too:
    ``label ... 42 s (20,000 of 200,000 steps, about 6 min left)``."""
    import sys
    import threading
    import time

    stream = stream or sys.stdout
    live = stream.isatty()
    interval = every if every is not None else (1.0 if live else 30.0)
    start, done = time.perf_counter(), threading.Event()

    def tick():
        while not done.wait(interval):
            elapsed = time.perf_counter() - start
            text = f"{label} ... {elapsed:.0f} s"
            if counter is not None and total and counter.done:
                left = elapsed * (total - counter.done) / counter.done
                text += f" ({counter.done:,} of {total:,} steps, about {_minutes(left)} left)"
            stream.write(f"\r{text}" if live else f"{text}\n")
            stream.flush()

    print(f"{label} ...", file=stream, end="" if live else "\n", flush=True)
    thread = threading.Thread(target=tick, daemon=True)
    thread.start()
    try:
        yield
    finally:
        done.set()
        thread.join()
        if live:
            stream.write("\n")


def _minutes(seconds: float) -> str:
    """A time left, as a person reads it: ``40 s``, ``6 min``, ``2 h 5 min``."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    minutes = round(seconds / 60)
    return f"{minutes} min" if minutes < 60 else f"{minutes // 60} h {minutes % 60} min"
