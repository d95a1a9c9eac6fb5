"""The ``Demonstrations`` type: rows of observations, actions and confidences, validated on
construction (shapes, finite numbers, confidences in [0, 1], actions within
``ACTION_BOUND_MULTIPLE`` times an environment's bounds), and ``DemonstrationError``, the one
error every loader raises, naming the file, its role and the problem."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from pngail_jax.config.released_files import RELEASED_TASKS
from pngail_jax.envs import ENV_NAMES, task_family

# ``check_env`` refuses actions beyond this multiple of the bound's magnitude: a unit or file
# mix-up, not exploration noise. The authors' MuJoCo files store unclipped policy actions, with
# 19-58% of entries outside [-1, 1] and values up to 6.65, so a small excess is normal.
ACTION_BOUND_MULTIPLE = 10.0


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
            object.__setattr__(self, "confidence", confidence_vector(self.confidence, len(obs)))
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


def confidence_vector(values, num_rows: int) -> np.ndarray:
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
