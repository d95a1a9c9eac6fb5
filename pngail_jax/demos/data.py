"""The ``Demonstrations`` type, its validation, loaders and savers, and vmappable splits.

Two on-disk layouts:

- The paper's released layout: ``{env}_mixture.npy`` of shape (N, obs_dim + act_dim), rows
  ``[s, a]``, and ``{env}_mixture_conf.npy`` of shape (N, 1). The released Pendulum set stores
  the torque divided by 2; loaded by its name it is multiplied by 2 (``action_scale`` None),
  ``action_scale=1`` keeps the rows as stored (``docs/demonstrations.md``). Any other ``.npy``
  of rows ``[s, a]`` loads the same way, given the observation size (an environment's) and
  optionally a confidence file.
- Our ``.npz`` schema, version 1: arrays ``observations`` float32[N, O], ``actions``
  float32[N, A], optional ``confidence`` float32[N], ``labelled`` bool[N],
  ``trajectory_ids`` int32[N], plus ``metadata_json`` (a JSON string) and ``format_version``.

``load_demonstrations`` also reads a local Minari dataset, ``"minari:<dataset_id>"``, with
per-episode confidences from a file or an episode metadata field (``load_minari``).

Every file is read through one helper (``_load_numpy``) with ``allow_pickle=False``; an
empty, truncated or corrupt file, pickled objects, strings or a missing array end in a
``DemonstrationError`` that names the file, its role and the problem.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import Any

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from pngail_jax.envs import ENV_NAMES, task_family

NPZ_FORMAT_VERSION = 1

# ``load_demonstrations("minari:<dataset_id>")`` loads a local Minari dataset.
MINARI_PREFIX = "minari:"

# Observation sizes of the paper's released files (gym -v2 MuJoCo tasks), to split [s, a].
RELEASED_OBSERVATION_SIZES = {
    "Pendulum-v1": 3,
    "Ant-v2": 111,
    "HalfCheetah-v2": 17,
    "Hopper-v2": 11,
    "Swimmer-v2": 8,
    "Walker2d-v2": 17,
}

# Action sizes of the same files: a row holds observation + action columns.
RELEASED_ACTION_SIZES = {
    "Pendulum-v1": 1,
    "Ant-v2": 8,
    "HalfCheetah-v2": 6,
    "Hopper-v2": 3,
    "Swimmer-v2": 2,
    "Walker2d-v2": 6,
}

# Our task of each released file's environment: gymnasium's -v4 tasks, which have gym -v2's
# model files and observation layouts. The authors' Ant-v2 file has none: gym v2's Ant
# observations (111: positions, velocities and contact forces) are not Ant-v4's (27).
RELEASED_TASKS = {
    "Pendulum-v1": "Pendulum-v1",
    "HalfCheetah-v2": "HalfCheetah-v4",
    "Hopper-v2": "Hopper-v4",
    "Swimmer-v2": "Swimmer-v4",
    "Walker2d-v2": "Walker2d-v4",
}

# The documented layout of the released files whose rows are whole trajectories stored one
# after another: the Pendulum file is five 200-step episodes. The MuJoCo files are not
# trajectories (the paper says so): they get no trajectory ids.
RELEASED_TRAJECTORY_LENGTHS = {"Pendulum-v1": 200}

# What the stored actions of a released file must be multiplied by to be in the environment's
# units (the authors' Pendulum file stores torque / 2); 1 for the others.
RELEASED_ACTION_SCALES = {"Pendulum-v1": 2.0}


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


# ``check_env`` refuses actions beyond this multiple of the bound's magnitude: a unit or file
# mix-up, not exploration noise. The authors' MuJoCo files store unclipped policy actions, with
# 19-58% of entries outside [-1, 1] and values up to 6.65, so a small excess is normal.
ACTION_BOUND_MULTIPLE = 10.0

# The first bytes of a .npy file and of a .npz (zip) archive.
NPY_MAGIC = b"\x93NUMPY"
ZIP_MAGICS = (b"PK\x03\x04", b"PK\x05\x06")

# The paper's Table 3: (random policy, optimal policy) returns, the normaliser of its figures.
PAPER_NORMALIZERS = {
    "Pendulum-v1": (-1200.96, -116.81),
    "Ant-v2": (-72.30, 4143.10),
    "HalfCheetah-v2": (-288.44, 3467.32),
    "Hopper-v2": (18.04, 3250.67),
    "Swimmer-v2": (2.31, 348.99),
    "Walker2d-v2": (1.91, 3694.13),
}


class DemonstrationError(ValueError):
    """Demonstrations that cannot be used as given; the message names the problem."""


@dataclasses.dataclass(frozen=True)
class Demonstrations:
    """State-action pairs with optional per-row confidence that the pair is optimal.

    Attributes:
      observations: float32[N, observation_size].
      actions: float32[N, action_size], in the environment's units.
      confidence: float32[N] in [0, 1], or None.
      labelled: bool[N], rows whose confidence a learner may see (default: all, when
        confidence is given).
      trajectory_ids: int32[N] or None.
      metadata: environment name, action scale, random / optimal returns for normalisation,
        and how the set was made.
    """

    observations: np.ndarray
    actions: np.ndarray
    confidence: np.ndarray | None = None
    labelled: np.ndarray | None = None
    trajectory_ids: np.ndarray | None = None
    metadata: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        obs = _float_matrix("observations", self.observations)
        actions = _float_matrix("actions", self.actions)
        if len(obs) != len(actions):
            raise DemonstrationError(
                f"observations has {len(obs)} rows but actions has {len(actions)}"
            )
        if len(obs) == 0:
            raise DemonstrationError("no demonstration rows")
        object.__setattr__(self, "observations", obs)
        object.__setattr__(self, "actions", actions)
        if self.confidence is not None:
            object.__setattr__(self, "confidence", _confidence_vector(self.confidence, len(obs)))
        if self.labelled is not None:
            labelled = np.asarray(self.labelled)
            _check_rows("labelled", labelled, len(obs), ndim=1)
            if labelled.dtype != np.bool_:
                raise DemonstrationError(f"labelled must be a bool mask, got {labelled.dtype}")
            if self.confidence is None and labelled.any():
                raise DemonstrationError("labelled rows given but no confidence")
            object.__setattr__(self, "labelled", labelled)
        if self.trajectory_ids is not None:
            ids = np.asarray(self.trajectory_ids)
            _check_rows("trajectory_ids", ids, len(obs), ndim=1)
            if not np.issubdtype(ids.dtype, np.integer):
                raise DemonstrationError(f"trajectory_ids must be integers, got {ids.dtype}")
            object.__setattr__(self, "trajectory_ids", ids.astype(np.int32))

    @property
    def num_rows(self) -> int:
        return len(self.observations)

    @property
    def inputs(self) -> np.ndarray:
        """float32[N, observation_size + action_size]: rows [s, a]."""
        return np.concatenate([self.observations, self.actions], axis=1)

    def rows_beyond(self, low, high) -> np.ndarray:
        """bool[N]: rows with an action outside ``[low, high]`` in some dimension."""
        return ((self.actions < low) | (self.actions > high)).any(axis=1)

    def clipped(self, low, high) -> Demonstrations:
        """These demonstrations with every action clipped to ``[low, high]`` (float32[A]
        each): the action the environment applies, since the physics clamps controls to
        their range. Unchanged (the same arrays) when every action is already inside."""
        if not self.rows_beyond(low, high).any():
            return self
        actions = np.clip(self.actions, low, high).astype(np.float32)
        return dataclasses.replace(self, actions=actions)

    def check_env(self, env) -> None:
        """Raises ``DemonstrationError`` unless the sizes match ``env``'s and no action lies
        beyond ``ACTION_BOUND_MULTIPLE`` times the magnitude of ``env``'s action bound
        (``max(|low|, |high|)`` per dimension). Actions a little outside the bounds pass: the
        released MuJoCo sets store unclipped policy actions. A released file of another task
        than ``env`` (``RELEASED_TASKS``; any variant of the same task, ``envs.task_family``,
        fits), or the unusable Ant-v2 file, is named as such."""
        made_for = self.metadata.get("env")
        if made_for == "Ant-v2":
            raise DemonstrationError(
                "the authors' Ant-v2 file cannot serve: gym v2's Ant observations have 111 "
                "columns (with contact forces), our Ant's have "
                f"{env.observation_size}; make Ant demonstrations with experiments.make_demos"
            )
        task = RELEASED_TASKS.get(made_for, made_for)
        if task in ENV_NAMES and task_family(task) != task_family(env.name):
            raise DemonstrationError(
                f"demonstrations of {made_for} do not fit {env.name}: pick the task {task} "
                "(--env), or demonstrations of this one"
            )
        if self.observations.shape[1] != env.observation_size:
            raise DemonstrationError(
                f"demonstrations have observations of size "
                f"{self.observations.shape[1]}, {env.name} has "
                f"{env.observation_size}"
            )
        if self.actions.shape[1] != env.action_size:
            raise DemonstrationError(
                f"demonstrations have actions of size "
                f"{self.actions.shape[1]}, {env.name} has {env.action_size}"
            )
        bound = np.maximum(np.abs(env.action_low), np.abs(env.action_high)).astype(np.float64)
        magnitude = np.abs(self.actions)
        beyond = magnitude > ACTION_BOUND_MULTIPLE * bound
        if beyond.any():
            row, column = np.unravel_index(np.argmax(np.where(beyond, magnitude, -1)), beyond.shape)
            raise DemonstrationError(
                f"actions reach {self.actions[row, column]:.4g} (row {row}, dimension {column}), "
                f"more than {ACTION_BOUND_MULTIPLE:g} x the action bound {bound[column]:.4g} of "
                f"{env.name}: wrong --action-scale, or actions stored in other units?"
            )


def _float_matrix(name: str, values) -> np.ndarray:
    values = np.asarray(values)
    if values.ndim != 2:
        raise DemonstrationError(f"{name} must be 2-D (rows, features), got shape {values.shape}")
    if not np.issubdtype(values.dtype, np.floating):
        raise DemonstrationError(f"{name} must be floating point, got {values.dtype}")
    with np.errstate(over="ignore"):  # values beyond float32's range become inf: refused
        stored = values.astype(np.float32)
    if not np.isfinite(stored).all():
        row, column = np.argwhere(~np.isfinite(stored))[0]
        beyond = np.isfinite(values[row, column])
        raise DemonstrationError(
            f"{name} contains NaN or infinite values (first at row {row}, column {column}"
            f"{f': {values[row, column]:.3g}, beyond float32' if beyond else ''})"
        )
    return stored


def _check_rows(name: str, values: np.ndarray, num_rows: int, ndim: int) -> None:
    if values.ndim != ndim or len(values) != num_rows:
        raise DemonstrationError(f"{name} must have shape ({num_rows},), got {values.shape}")


def _confidence_vector(values, num_rows: int) -> np.ndarray:
    """float32[num_rows] confidences in [0, 1] from float[num_rows] or float[num_rows, 1]."""
    confidence = np.asarray(values)
    if confidence.ndim == 2 and confidence.shape[1] == 1:
        confidence = confidence[:, 0]
    _check_rows("confidence", confidence, num_rows, ndim=1)
    if not np.issubdtype(confidence.dtype, np.floating):
        raise DemonstrationError(f"confidence must be floating point, got {confidence.dtype}")
    if not np.isfinite(confidence).all():
        raise DemonstrationError("confidence contains NaN or infinite values")
    if confidence.min() < 0 or confidence.max() > 1:
        raise DemonstrationError(
            f"confidence must lie in [0, 1], got values in "
            f"[{confidence.min():.3g}, {confidence.max():.3g}]"
        )
    return confidence.astype(np.float32)


def _load_numpy(path: str | Path, role: str, *, archive: bool = False):
    """The array of a ``.npy`` file (``archive=False``) or the arrays of a ``.npz`` archive (a
    dict by name), read with ``allow_pickle=False``.

    Raises ``FileNotFoundError`` for a missing file and ``DemonstrationError`` for anything
    else that is not a clean NumPy file (empty, truncated, corrupt, pickled objects; for a
    ``.npy`` file also values that are not real numbers), each message naming ``role`` (e.g.
    ``"mixture file"``) and ``path``.
    """
    path = Path(path)
    where = f"{role} {path}"
    if not path.exists():
        raise FileNotFoundError(f"{role} not found: {path}")
    if path.is_dir():
        raise DemonstrationError(f"{where}: is a directory, not a file")
    num_bytes = path.stat().st_size
    if num_bytes == 0:
        raise DemonstrationError(f"{where}: is empty (0 bytes)")
    with path.open("rb") as stream:
        start = stream.read(len(NPY_MAGIC))
        stream.seek(0)
        if start.startswith(ZIP_MAGICS) != archive:
            raise DemonstrationError(f"{where}: {_wrong_container(start, archive)}")
        problem = None if archive else _npy_problem(stream, num_bytes)
    if problem:
        raise DemonstrationError(f"{where}: {problem}")
    try:
        return _read_npz(path, where) if archive else _read_npy(path, where)
    except DemonstrationError:
        raise
    except (
        OSError,
        EOFError,
        ValueError,
        KeyError,
        NotImplementedError,
        RuntimeError,
        zipfile.BadZipFile,
        zlib.error,
    ) as error:
        kind = "NumPy .npz archive" if archive else "NumPy .npy file"
        detail = (str(error).splitlines() or [type(error).__name__])[0][:200]
        raise DemonstrationError(
            f"{where}: not a readable {kind}, truncated or corrupt ({detail})"
        ) from None


def _wrong_container(start: bytes, archive: bool) -> str:
    if not archive:
        return "is a .npz archive, expected a .npy file"
    kind = "a .npy file" if start == NPY_MAGIC else "not a zip archive"
    return f"not a NumPy .npz archive ({kind})"


def _read_npy(path: Path, where: str) -> np.ndarray:
    array = np.load(path, allow_pickle=False)
    if array.dtype.kind not in "biuf":
        raise DemonstrationError(f"{where}: {_not_numbers(array)}")
    return array


def _read_npz(path: Path, where: str) -> dict[str, np.ndarray]:
    """Every ``.npy`` member of the archive, each checked by its header before it is read."""
    arrays = {}
    with np.load(path, allow_pickle=False) as npz:
        for info in npz.zip.infolist():
            if not info.filename.endswith(".npy"):
                continue  # np.savez writes only .npy members; others are not ours
            name = info.filename.removesuffix(".npy")
            with npz.zip.open(info) as member:
                problem = _npy_problem(member, info.file_size)
            if problem:
                raise DemonstrationError(f"{where}: array {name!r} {problem}")
            arrays[name] = npz[name]
    return arrays


def _npy_problem(stream, num_bytes: int) -> str | None:
    """What is wrong with the ``.npy`` data of ``num_bytes`` bytes at ``stream``'s start, read
    from its header alone (no data is read), or None when the header is sound."""
    try:
        version = np.lib.format.read_magic(stream)
    except ValueError:
        return "is not a NumPy .npy file (bad header)"
    if version not in ((1, 0), (2, 0), (3, 0)):
        return f"is not a NumPy .npy file (unknown format version {version[0]}.{version[1]})"
    # Version 3.0 differs from 2.0 only in decoding non-ASCII field names, which no array of
    # numbers has.
    read_header = (
        np.lib.format.read_array_header_1_0
        if version == (1, 0)
        else np.lib.format.read_array_header_2_0
    )
    try:
        shape, _, dtype = read_header(stream)
    except Exception:  # untrusted bytes: any failure to parse the header means a corrupt one
        return "is not a NumPy .npy file (corrupt header)"
    if dtype.hasobject:
        return "holds pickled Python objects, which are not loaded for safety"
    if any(size < 0 for size in shape):
        return f"is not a NumPy .npy file (corrupt header: shape {shape})"
    expected = math.prod(shape) * dtype.itemsize
    found = num_bytes - stream.tell()
    if found < expected:
        return (
            f"is truncated: expected {expected} bytes of data for shape {shape} "
            f"{dtype}, found {found}"
        )
    return None


def _not_numbers(array: np.ndarray) -> str:
    kinds = {"U": "strings", "S": "bytes", "c": "complex numbers", "M": "dates", "m": "times"}
    what = kinds.get(array.dtype.kind, "values")
    return f"holds {what} (dtype {array.dtype}), expected real numbers"


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
    mixture_path = Path(mixture_path)
    if mixture_path.suffix != ".npy":
        raise DemonstrationError(
            f"{mixture_path}: expected a .npy file of rows [observation, action], an .npz set "
            "or minari:<dataset id>"
        )
    named = mixture_path.name.endswith("_mixture.npy")
    env_name = mixture_path.name.removesuffix("_mixture.npy") if named else None
    action_scale, source = _action_scale(env_name, action_scale)
    if conf_path is None and named:
        conf_path = released_confidence_path(mixture_path)
    where = f"{'mixture' if named else 'rows'} file {mixture_path}"
    rows, observation_size = _rows(mixture_path, where, env_name, observation_size, action_size)
    confidence = None if conf_path is None else _load_numpy(conf_path, "confidence file")
    if confidence is not None:
        confidence = _released_confidence(confidence, conf_path, mixture_path, len(rows))
    metadata = {
        **({"env": env_name} if named else {}),
        "action_scale": float(action_scale),
        "action_scale_source": source,
        "source": f"{'released layout' if named else 'rows'}: {mixture_path.name}",
    }
    if env_name in PAPER_NORMALIZERS:
        random_return, optimal_return = PAPER_NORMALIZERS[env_name]
        metadata |= {
            "random_return": random_return,
            "optimal_return": optimal_return,
            "normalizer_source": "paper Table 3",
        }
    trajectory_ids, trajectory_length = _trajectories(
        env_name, trajectory_length, confidence, len(rows), where
    )
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
    rows = _load_numpy(path, where.removesuffix(f" {path}"))
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
        return _confidence_vector(confidence, num_rows)
    except DemonstrationError as error:
        raise DemonstrationError(f"{where}: {error}") from None


def save_npz(path: str | Path, demos: Demonstrations) -> None:
    arrays = {"observations": demos.observations, "actions": demos.actions}
    for name in ("confidence", "labelled", "trajectory_ids"):
        if getattr(demos, name) is not None:
            arrays[name] = getattr(demos, name)
    np.savez(
        path,
        **arrays,
        metadata_json=np.asarray(json.dumps(demos.metadata)),
        format_version=np.asarray(NPZ_FORMAT_VERSION),
    )


def load_npz(path: str | Path) -> Demonstrations:
    """Loads our ``.npz`` schema (module docstring); errors name the file."""
    where = f"demonstrations .npz {path}"
    arrays = _load_numpy(path, "demonstrations .npz", archive=True)
    if "format_version" not in arrays:
        raise DemonstrationError(
            f"{where}: has no array 'format_version' (not written by save_npz? this version "
            f"reads format_version {NPZ_FORMAT_VERSION})"
        )
    version = arrays["format_version"]
    if version.shape != () or version.dtype.kind not in "iu":
        raise DemonstrationError(
            f"{where}: format_version must be one integer, got {version.dtype} of shape "
            f"{version.shape}"
        )
    version = int(version)
    if version != NPZ_FORMAT_VERSION:
        raise DemonstrationError(
            f"{where}: unsupported format_version {version!r} "
            f"(this version reads {NPZ_FORMAT_VERSION})"
        )
    for name in ("observations", "actions"):
        if name not in arrays:
            raise DemonstrationError(
                f"{where}: has no array {name!r} (it has {', '.join(sorted(arrays))})"
            )
    fields = {
        name: arrays[name]
        for name in ("observations", "actions", "confidence", "labelled", "trajectory_ids")
        if name in arrays
    }
    for name, array in fields.items():
        if array.dtype.kind not in "biuf":
            raise DemonstrationError(f"{where}: array {name!r} {_not_numbers(array)}")
    metadata = _npz_metadata(arrays.get("metadata_json"), where)
    try:
        return Demonstrations(metadata=metadata, **fields)
    except DemonstrationError as error:
        raise DemonstrationError(f"{where}: {error}") from None


def _npz_metadata(metadata_json: np.ndarray | None, where: str) -> dict[str, Any]:
    """The metadata dict of an ``.npz`` file's ``metadata_json`` (empty when absent), with
    usable random / optimal returns when it has both; raises naming ``where``."""
    if metadata_json is None:
        return {}
    if metadata_json.shape != () or metadata_json.dtype.kind != "U":
        raise DemonstrationError(
            f"{where}: metadata_json must be one string, got {metadata_json.dtype} of shape "
            f"{metadata_json.shape}"
        )
    try:
        metadata = json.loads(str(metadata_json))
    except ValueError as error:
        raise DemonstrationError(f"{where}: metadata_json is not valid JSON ({error})") from None
    if not isinstance(metadata, dict):
        raise DemonstrationError(f"{where}: metadata_json must be a JSON object")
    if "random_return" in metadata and "optimal_return" in metadata:
        returns = metadata["random_return"], metadata["optimal_return"]
        numbers = all(isinstance(x, int | float) and not isinstance(x, bool) for x in returns)
        if not (numbers and all(math.isfinite(x) for x in returns) and returns[0] != returns[1]):
            raise DemonstrationError(
                f"{where}: metadata random_return {returns[0]!r} and optimal_return "
                f"{returns[1]!r} must be two different finite numbers (normalised returns "
                "divide by their difference)"
            )
        if returns[0] > returns[1]:  # make_demos at a tiny budget: usable, but say so
            warnings.warn(
                f"{where}: its optimal_return {returns[1]:.1f} is below its random_return "
                f"{returns[0]:.1f}: normalised returns run backwards (make it with more "
                "--iterations)",
                stacklevel=3,
            )
    return metadata


def load_demonstrations(
    path: str | Path,
    conf_path: str | Path | None = None,
    action_scale: float | None = None,
    *,
    confidence_field: str | None = None,
    observation_size: int | None = None,
    action_size: int | None = None,
) -> Demonstrations:
    """Loads ``*_mixture.npy``, ``*.npz`` or ``"minari:<dataset_id>"``, a local Minari dataset.

    ``action_scale`` multiplies stored actions; None: the known scale of an authors' file
    (``load_released``), 1 for a Minari dataset. A ``.npy`` of rows [s, a] that is not an
    authors' file is split by ``observation_size`` (and checked against ``action_size``), an
    environment's sizes. An ``.npz`` set is in the environment's units
    already: it takes no scale other than None or 1.

    For a Minari dataset, per-episode confidences come from ``conf_path`` (a ``.npy`` file or a
    text file, one number per episode and line, in episode order) or from the episode metadata
    field ``confidence_field`` (``load_minari``); with neither, ``confidence`` is None.
    """
    if str(path).startswith(MINARI_PREFIX):
        return load_minari(
            str(path).removeprefix(MINARI_PREFIX),
            conf_path,
            confidence_field=confidence_field,
            action_scale=1.0 if action_scale is None else action_scale,
        )
    if confidence_field is not None:
        raise DemonstrationError(
            f"{path}: confidence_field is for Minari datasets ('{MINARI_PREFIX}<dataset_id>')"
        )
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"demonstrations not found: {path}")
    if path.suffix == ".npz":
        if action_scale not in (None, 1.0):
            raise DemonstrationError(
                f"{path}: an .npz set is stored in the environment's units: no action_scale"
            )
        return load_npz(path)
    return load_released(
        path, conf_path, action_scale, observation_size=observation_size, action_size=action_size
    )


@struct.dataclass
class Split:
    """One seed's D_c / D_u split of ``traj_size`` rows; leaves are [traj_size]."""

    indices: jax.Array  # int32, rows of the full set
    confidence: jax.Array  # float32, confidences the learner sees (after any noise)
    true_confidence: jax.Array  # float32, before noise (for MAE / RMSE)
    labelled: jax.Array  # bool, D_c


def make_split(
    key: jax.Array,
    confidence: jax.Array,
    traj_size: int,
    label_ratio: float | jax.Array,
    noise_std: float | jax.Array = 0.0,
    allowed: jax.Array | None = None,
) -> Split:
    """Draws ``traj_size`` rows; the first ``round(label_ratio * traj_size)`` are labelled.

    ``allowed`` (bool[N], None = every row) marks the rows whose confidence a learner may see
    (``Demonstrations.labelled``). The rows are drawn uniformly as without it; the drawn
    allowed rows then come first, each group in drawn order, and only they are labelled: the
    first ``min(round(label_ratio * traj_size), allowed rows drawn)``. With every row allowed
    the split is the one drawn without ``allowed``, bit for bit.

    Confidence noise ``clip(r + N(0, noise_std^2), 0, 1)`` as the paper's robustness test.
    ``traj_size`` is static (a shape); ``label_ratio``, ``noise_std`` and ``allowed`` are
    values, so a grid can vmap over them.
    """
    order_key, noise_key = jax.random.split(key)
    indices = jax.random.permutation(order_key, confidence.shape[0])[:traj_size]
    num_labelled = jnp.round(label_ratio * traj_size)
    if allowed is not None:
        chex.assert_shape(allowed, confidence.shape[:1])
        allowed_drawn = jnp.asarray(allowed, bool)[indices]
        # A stable sort keeps the drawn order within each group: all allowed = no reordering.
        indices = indices[jnp.argsort((~allowed_drawn).astype(jnp.int32), stable=True)]
        num_labelled = jnp.minimum(num_labelled, allowed_drawn.sum())
    true_confidence = confidence[indices]
    noise = noise_std * jax.random.normal(noise_key, true_confidence.shape)
    return Split(
        indices=indices.astype(jnp.int32),
        confidence=jnp.clip(true_confidence + noise, 0.0, 1.0),
        true_confidence=true_confidence,
        labelled=jnp.arange(traj_size) < num_labelled,
    )


def load_minari(
    dataset_id: str,
    confidence=None,
    *,
    confidence_field: str | None = None,
    action_scale: float = 1.0,
) -> Demonstrations:
    """Loads a *local* Minari dataset (never downloads) as demonstrations.

    Minari stores T + 1 observations per episode; the final one is dropped so rows are
    (s_t, a_t) pairs. Minari stores no confidence; give it per episode, in the dataset's
    episode order, as either
      ``confidence``: one value for all rows, one value per episode, or the path of a ``.npy``
        file or a text file with one number per episode (one per line); or
      ``confidence_field``: the name of an episode metadata field, written with Minari's
        ``dataset.storage.update_episode_metadata`` or a ``DataCollector``'s
        ``episode_metadata_callback`` (``docs/demonstrations.md``).
    ``action_scale`` multiplies the stored actions. Needs the optional dependency:
    ``pip install 'pngail-jax[minari]'``. Datasets are found in ``MINARI_DATASETS_PATH``
    (default ``~/.minari/datasets``).
    """
    try:
        import minari
    except ImportError as error:
        raise ImportError("load_minari needs minari: pip install 'pngail-jax[minari]'") from error
    if confidence is not None and confidence_field is not None:
        raise DemonstrationError("give confidence or confidence_field, not both")
    if not (math.isfinite(action_scale) and action_scale > 0):
        raise DemonstrationError(f"action_scale must be positive and finite, got {action_scale!r}")
    try:
        dataset = minari.load_dataset(dataset_id, download=False)
    except FileNotFoundError as error:
        raise DemonstrationError(f"no local Minari dataset {dataset_id!r}: {error}") from None
    observations, actions, ids = [], [], []
    for index, episode in enumerate(dataset.iterate_episodes()):
        if not isinstance(episode.observations, np.ndarray):
            raise DemonstrationError(f"{dataset_id}: only flat Box observations are supported")
        steps = len(episode.actions)
        observations.append(np.asarray(episode.observations[:steps], np.float32))
        actions.append(np.asarray(episode.actions, np.float32).reshape(steps, -1))
        ids.append(np.full(steps, index, np.int32))
    ids = np.concatenate(ids)
    if isinstance(confidence, str | Path):
        source = str(confidence)
        confidence = _read_numbers(confidence)
    elif confidence_field is not None:
        source = f"{dataset_id}: episode metadata field {confidence_field!r}"
        confidence = _metadata_field(dataset, dataset_id, confidence_field)
    else:
        source = "confidence (one value or one per episode)"
        if confidence is not None and np.ndim(confidence) == 0:
            confidence = np.full(len(observations), confidence)
    if confidence is not None:
        confidence = _per_episode(source, confidence, len(observations), dataset_id)[ids]
    return Demonstrations(
        observations=np.concatenate(observations),
        actions=np.concatenate(actions) * action_scale,
        confidence=confidence,
        trajectory_ids=ids,
        metadata={"source": f"minari: {dataset_id}", "action_scale": float(action_scale)},
    )


def _read_numbers(path: str | Path) -> np.ndarray:
    """The numbers of a ``.npy`` file, or of a text file with one number per line."""
    path = Path(path)
    if path.suffix == ".npy":
        return _load_numpy(path, "confidence file")
    try:
        return np.loadtxt(path, ndmin=1)
    except ValueError as error:
        raise DemonstrationError(
            f"confidence file {path}: expected one number per line: {error}"
        ) from None


def _metadata_field(dataset, dataset_id: str, field: str) -> list:
    """The value of ``field`` in each episode's metadata, in episode order."""
    values = []
    indices = dataset.episode_indices
    for index, episode in zip(indices, dataset.storage.get_episode_metadata(indices), strict=True):
        if field not in episode:
            raise DemonstrationError(
                f"{dataset_id}: episode {index} has no metadata field {field!r} "
                f"(it has {', '.join(sorted(episode))})"
            )
        values.append(episode[field])
    return values


def _per_episode(source: str, values, num_episodes: int, dataset_id: str) -> np.ndarray:
    """float32[num_episodes] confidences from ``values``, or raises naming ``source``."""
    try:
        values = np.asarray(values, np.float64)
    except (TypeError, ValueError):
        raise DemonstrationError(f"{source}: confidences must be numbers") from None
    if values.ndim == 2 and values.shape[1] == 1:
        values = values[:, 0]
    if values.shape != (num_episodes,):
        raise DemonstrationError(
            f"{source}: {values.size} confidences for the {num_episodes} episodes of Minari "
            f"dataset {dataset_id!r}"
        )
    if np.isnan(values).any():
        raise DemonstrationError(f"{source}: confidences contain NaN")
    if values.min() < 0 or values.max() > 1:
        raise DemonstrationError(
            f"{source}: confidences must lie in [0, 1], got values in "
            f"[{values.min():.3g}, {values.max():.3g}]"
        )
    return values.astype(np.float32)
