"""Imperfect demonstrations: the ``Demonstrations`` type, loaders, savers and splits.

By job: ``types`` (``Demonstrations``, ``DemonstrationError``), ``files`` (safe .npy/.npz
parsing), ``released`` (the authors' files), ``npz`` (our schema), ``minari``, ``splits``,
``data`` (``load_demonstrations``, any source by name), ``tables`` (the authors' files as
data) and ``generate`` (rollouts, returns). Making demonstrations from scratch is a job:
``pngail_jax.jobs.make_demos``.
"""

from pngail_jax.demos.data import load_demonstrations
from pngail_jax.demos.minari import load_minari
from pngail_jax.demos.npz import load_npz, save_npz
from pngail_jax.demos.released import (
    RELEASED_ACTION_SCALES,
    RELEASED_TASKS,
    action_scale_note,
    load_released,
    released_confidence_path,
    released_task,
)
from pngail_jax.demos.splits import Split, cut_mixture, make_split, successor_rows
from pngail_jax.demos.types import ACTION_BOUND_MULTIPLE, DemonstrationError, Demonstrations

__all__ = [
    "ACTION_BOUND_MULTIPLE",
    "RELEASED_ACTION_SCALES",
    "action_scale_note",
    "RELEASED_TASKS",
    "DemonstrationError",
    "Demonstrations",
    "Split",
    "cut_mixture",
    "load_demonstrations",
    "load_minari",
    "load_npz",
    "load_released",
    "make_split",
    "successor_rows",
    "released_confidence_path",
    "released_task",
    "save_npz",
]
