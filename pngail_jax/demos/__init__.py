"""Imperfect demonstrations: the ``Demonstrations`` type, loaders, savers and splits."""

from pngail_jax.demos.data import (
    ACTION_BOUND_MULTIPLE,
    RELEASED_ACTION_SCALES,
    RELEASED_TASKS,
    DemonstrationError,
    Demonstrations,
    Split,
    action_scale_note,
    load_demonstrations,
    load_minari,
    load_npz,
    load_released,
    make_split,
    released_confidence_path,
    released_task,
    save_npz,
)

__all__ = [
    "ACTION_BOUND_MULTIPLE",
    "RELEASED_ACTION_SCALES",
    "action_scale_note",
    "RELEASED_TASKS",
    "DemonstrationError",
    "Demonstrations",
    "Split",
    "load_demonstrations",
    "load_minari",
    "load_npz",
    "load_released",
    "make_split",
    "released_confidence_path",
    "released_task",
    "save_npz",
]
