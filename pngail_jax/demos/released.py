"""The paper's released layout: ``{env}_mixture.npy`` of shape (N, obs_dim + act_dim), rows
``[s, a]``, and ``{env}_mixture_conf.npy`` of shape (N, 1). The released Pendulum set stores the
torque divided by 2; loaded by its name it is multiplied by 2 (``action_scale`` None),
``action_scale=1`` keeps the rows as stored (``docs/demonstrations.md``). Any other ``.npy`` of
rows ``[s, a]`` loads the same way, given the observation size (an environment's) and
optionally a confidence file. The paper's Table 3 return ranges (random and optimal returns)
come with the authors' files."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pngail_jax.config.released_files import (  # noqa: F401  (the tables, importable from here too)
    PAPER_NORMALIZERS,
    PAPER_RETURN_RANGES,
    RELEASED_ACTION_SCALES,
    RELEASED_ACTION_SIZES,
    RELEASED_OBSERVATION_SIZES,
    RELEASED_TASKS,
    RELEASED_TRAJECTORY_LENGTHS,
)
from pngail_jax.demos.files import load_numpy
from pngail_jax.demos.types import DemonstrationError, Demonstrations, confidence_vector


def action_scale_note(demos) -> str | None:
    """One line saying that an authors' file's known action scale was applied (for the
    terminal), or None when the scale was given or is 1."""
    if demos.metadata.get("action_scale_source") != "known":
        return None
    scale = demos.metadata["action_scale"]
    name = demos.metadata.get("source", "").removeprefix("released layout: ")
    return (
        f"note: {name} is the authors' file, which stores actions divided by {scale:g}: they "
        f"are multiplied by {scale:g} (--action-scale overrides)"
    )


def released_task(path: str | Path) -> str | None:
    """Our task of a released ``{env}_mixture.npy`` file (``RELEASED_TASKS``), else None."""
    name = Path(path).name
    return (
        RELEASED_TASKS.get(name.removesuffix("_mixture.npy"))
        if name.endswith("_mixture.npy")
        else None
    )


def released_confidence_path(mixture_path: str | Path) -> Path:
    """The confidence file beside an ``{env}_mixture.npy``: ``{env}_mixture_conf.npy``."""
    mixture_path = Path(mixture_path)
    return mixture_path.with_name(mixture_path.name.replace("_mixture.npy", "_mixture_conf.npy"))


def load_released(
    mixture_path: str | Path,
    conf_path: str | Path | None = None,
    action_scale: float | None = None,
    observation_size: int | None = None,
    trajectory_length: int | None = None,
    action_size: int | None = None,
) -> Demonstrations:
    """Loads the paper's ``{env}_mixture.npy`` (+ ``{env}_mixture_conf.npy``) layout, or any
    ``.npy`` of rows [s, a].

    ``trajectory_length`` splits the rows into consecutive trajectories of that many rows and
    fills ``trajectory_ids``: the row count must be a multiple of it and each trajectory must
    carry one confidence (a varying one means another layout), else ``DemonstrationError``.
    By default the file's documented layout (``RELEASED_TRAJECTORY_LENGTHS``: the Pendulum
    file's five 200-step episodes) is used when the file fits it, and no ids otherwise.

    ``conf_path`` defaults to the sibling ``*_mixture_conf.npy`` of a file so named; another
    file has no confidence without one. ``action_scale`` multiplies
    the stored action columns; None: the file's known scale (``RELEASED_ACTION_SCALES``: 2 for
    the authors' Pendulum file, whose torques are stored / 2), else 1. ``metadata`` records the
    scale applied and, under ``action_scale_source``, whether it was the known one.
    ``observation_size`` (an environment's; the sweep passes it) splits the rows, and
    ``action_size`` when given must be the remaining column count. Without it an authors'
    file (its name's environment in ``RELEASED_OBSERVATION_SIZES``) is split by that
    environment's observation size and must hold its number of action columns
    (``RELEASED_ACTION_SIZES``); any other file needs it.
    Errors name the rows or confidence file they are about.
    """
    mixture_path = _npy_path(mixture_path)
    named = mixture_path.name.endswith("_mixture.npy")
    env_name = mixture_path.name.removesuffix("_mixture.npy") if named else None
    action_scale, source = _action_scale(env_name, action_scale)
    if conf_path is None and named:
        conf_path = released_confidence_path(mixture_path)
    where = f"{'mixture' if named else 'rows'} file {mixture_path}"
    rows, observation_size = _rows(mixture_path, where, env_name, observation_size, action_size)
    confidence = None
    if conf_path is not None:
        confidence = load_numpy(conf_path, "confidence file")
        confidence = _released_confidence(confidence, conf_path, mixture_path, len(rows))
    trajectory_ids, trajectory_length = _trajectories(
        env_name, trajectory_length, confidence, len(rows), where
    )
    metadata = _metadata(mixture_path, env_name, action_scale, source)
    if trajectory_ids is not None:
        metadata["trajectory_length"] = trajectory_length
    with np.errstate(over="ignore"):  # an overflow to inf is refused below, naming the file
        actions = rows[:, observation_size:] * action_scale
    try:
        return Demonstrations(
            observations=rows[:, :observation_size],
            actions=actions,
            confidence=confidence,
            trajectory_ids=trajectory_ids,
            metadata=metadata,
        )
    except DemonstrationError as error:
        raise DemonstrationError(f"{where}: {error}") from None


def _npy_path(path: str | Path) -> Path:
    """``path`` as a Path, refused unless it names a ``.npy`` file."""
    path = Path(path)
    if path.suffix != ".npy":
        raise DemonstrationError(
            f"{path}: expected a .npy file of rows [observation, action], an .npz set "
            "or minari:<dataset id>"
        )
    return path


def _metadata(mixture_path: Path, env_name: str | None, action_scale: float, source: str):
    """A loaded file's ``Demonstrations.metadata``: its environment and the paper's Table 3
    returns for an authors' file, the action scale applied and where it came from."""
    metadata = {
        **({"env": env_name} if env_name is not None else {}),
        "action_scale": float(action_scale),
        "action_scale_source": source,
        "source": f"{'released layout' if env_name is not None else 'rows'}: {mixture_path.name}",
    }
    if env_name in PAPER_RETURN_RANGES:
        random_return, optimal_return = PAPER_RETURN_RANGES[env_name]
        metadata |= {
            "random_return": random_return,
            "optimal_return": optimal_return,
            "normalizer_source": "paper Table 3",
        }
    return metadata


def _action_scale(env_name: str | None, action_scale: float | None) -> tuple[float, str]:
    """The scale to apply and where it came from: "given", "known" (an authors' file's,
    ``RELEASED_ACTION_SCALES``) or "default" (1)."""
    source = "given"
    if action_scale is None:
        action_scale = RELEASED_ACTION_SCALES.get(env_name, 1.0)
        source = "known" if env_name in RELEASED_ACTION_SCALES else "default"
    if not (math.isfinite(action_scale) and action_scale > 0):
        raise DemonstrationError(f"action_scale must be positive and finite, got {action_scale!r}")
    return action_scale, source


def _rows(path: Path, where: str, env_name, observation_size, action_size):
    """(float[N, O + A] rows, O) of a rows file, split by the given sizes or an authors' file's
    known ones; raises naming the file when they do not fit or none are known."""
    sizes_of = "the environment's"
    if observation_size is None and env_name in RELEASED_OBSERVATION_SIZES:
        observation_size = RELEASED_OBSERVATION_SIZES[env_name]
        action_size = RELEASED_ACTION_SIZES[env_name]
        sizes_of = env_name
    elif observation_size is None:
        known = f"unknown environment {env_name!r}" if env_name else "not an authors' file"
        raise DemonstrationError(
            f"{where}: {known}; give the environment (--env; in Python, observation_size) "
            f"to split its rows [observation, action] (authors' files: "
            f"{', '.join(RELEASED_OBSERVATION_SIZES)})"
        )
    rows = load_numpy(path, where.removesuffix(f" {path}"))
    if rows.ndim == 2 and action_size is not None:
        if rows.shape[1] != observation_size + action_size:
            raise DemonstrationError(
                f"{where}: rows have {rows.shape[1]} columns, but {sizes_of} rows [s, a] have "
                f"{observation_size} + {action_size} columns (observation + action)"
            )
    if rows.ndim != 2 or not 0 < observation_size < rows.shape[1]:
        raise DemonstrationError(
            f"{where}: rows of shape {rows.shape} cannot be split "
            f"into {observation_size} observation columns and actions"
        )
    if len(rows) == 0:  # before the confidence file is read against it
        raise DemonstrationError(f"{where}: has no rows (shape {rows.shape})")
    return rows, observation_size


def _trajectories(env_name, trajectory_length, confidence, num_rows: int, where: str):
    """(int32[N] trajectory ids or None, their length): consecutive trajectories of the given
    length, else of the file's documented layout when it fits, else none."""
    if trajectory_length is not None:
        per_row = np.zeros(num_rows) if confidence is None else confidence
        return _consecutive_trajectories(per_row, trajectory_length, where), trajectory_length
    if env_name in RELEASED_TRAJECTORY_LENGTHS:
        length = RELEASED_TRAJECTORY_LENGTHS[env_name]
        try:
            return _consecutive_trajectories(confidence, length, where), length
        except DemonstrationError:  # not the documented layout: rows without trajectories
            pass
    return None, None


def _consecutive_trajectories(confidence: np.ndarray, length: int, where: str) -> np.ndarray:
    """int32[N] ids of consecutive ``length``-row trajectories, or raises naming the file."""
    if isinstance(length, bool) or not isinstance(length, int) or length < 1:
        raise DemonstrationError(f"trajectory_length must be a positive integer, got {length!r}")
    num_rows = len(confidence)
    if num_rows % length:
        raise DemonstrationError(
            f"{where}: {num_rows} rows are not whole trajectories of {length} rows"
        )
    per_trajectory = confidence.reshape(-1, length)
    varying = np.flatnonzero(np.ptp(per_trajectory, axis=1) > 0)
    if varying.size:
        first = int(varying[0])
        raise DemonstrationError(
            f"{where}: the confidence changes within rows {first * length}-"
            f"{(first + 1) * length - 1}, so they are not one {length}-row trajectory"
        )
    return np.repeat(np.arange(num_rows // length, dtype=np.int32), length)


def _released_confidence(
    confidence: np.ndarray, conf_path: Path, mixture_path: Path, num_rows: int
) -> np.ndarray:
    """float32[num_rows] from a confidence file's float[num_rows(, 1)], or raises naming it."""
    where = f"confidence file {conf_path}"
    if confidence.ndim == 2 and confidence.shape[1] == 1:
        confidence = confidence[:, 0]
    if confidence.ndim != 1:
        raise DemonstrationError(
            f"{where}: expected shape (N,) or (N, 1), one confidence per row, "
            f"got {confidence.shape}"
        )
    if len(confidence) != num_rows:
        raise DemonstrationError(
            f"{where}: has {len(confidence)} rows, but mixture file {mixture_path} has {num_rows}"
        )
    try:
        return confidence_vector(confidence, num_rows)
    except DemonstrationError as error:
        raise DemonstrationError(f"{where}: {error}") from None
