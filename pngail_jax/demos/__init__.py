"""Imperfect demonstrations: the ``Demonstrations`` type, loaders, savers and splits."""

from pngail_jax.demos.data import (
    ACTION_BOUND_MULTIPLE,
    DemonstrationError,
    Demonstrations,
    Split,
    load_demonstrations,
    load_minari,
    load_npz,
    load_released,
    make_split,
    released_confidence_path,
    save_npz,
)

__all__ = [
    "ACTION_BOUND_MULTIPLE",
    "DemonstrationError",
    "Demonstrations",
    "Split",
    "load_demonstrations",
    "load_minari",
    "load_npz",
    "load_released",
    "make_split",
    "released_confidence_path",
    "save_npz",
]
