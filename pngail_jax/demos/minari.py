"""A local Minari dataset, ``"minari:<dataset_id>"``, with per-episode confidences from a file
or an episode metadata field."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from pngail_jax.demos.files import read_numbers
from pngail_jax.demos.types import DemonstrationError, Demonstrations

# ``load_demonstrations("minari:<dataset_id>")`` loads a local Minari dataset.
MINARI_PREFIX = "minari:"


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
    observations, actions, ids, num_episodes = _episode_rows(dataset, dataset_id)
    if isinstance(confidence, str | Path):
        source = str(confidence)
        confidence = read_numbers(confidence)
    elif confidence_field is not None:
        source = f"{dataset_id}: episode metadata field {confidence_field!r}"
        confidence = _metadata_field(dataset, dataset_id, confidence_field)
    else:
        source = "confidence (one value or one per episode)"
        if confidence is not None and np.ndim(confidence) == 0:
            confidence = np.full(num_episodes, confidence)
    if confidence is not None:
        confidence = _per_episode(source, confidence, num_episodes, dataset_id)[ids]
    return Demonstrations(
        observations=observations,
        actions=actions * action_scale,
        confidence=confidence,
        trajectory_ids=ids,
        metadata={"source": f"minari: {dataset_id}", "action_scale": float(action_scale)},
    )


def _episode_rows(dataset, dataset_id: str):
    """Each episode's (s_t, a_t) rows, concatenated: observations float32[N, O] (an
    episode's last observation dropped), actions float32[N, A], episode ids int32[N], and
    the number of episodes."""
    observations, actions, ids = [], [], []
    for index, episode in enumerate(dataset.iterate_episodes()):
        if not isinstance(episode.observations, np.ndarray):
            raise DemonstrationError(f"{dataset_id}: only flat Box observations are supported")
        steps = len(episode.actions)
        observations.append(np.asarray(episode.observations[:steps], np.float32))
        actions.append(np.asarray(episode.actions, np.float32).reshape(steps, -1))
        ids.append(np.full(steps, index, np.int32))
    rows = np.concatenate(observations), np.concatenate(actions), np.concatenate(ids)
    return (*rows, len(ids))


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
