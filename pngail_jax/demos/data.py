"""``load_demonstrations``: any supported source by its name (the authors' ``.npy`` files and
plain rows, our ``.npz``, ``"minari:<id>"``). The package is split by job: ``types``
(``Demonstrations``), ``files`` (safe .npy/.npz parsing), ``released`` (the authors' layout),
``npz``, ``minari``, ``splits``; ``pngail_jax.demos`` exports what users need."""

from __future__ import annotations

from pathlib import Path

from pngail_jax.demos.minari import MINARI_PREFIX, load_minari
from pngail_jax.demos.npz import load_npz
from pngail_jax.demos.released import load_released
from pngail_jax.demos.types import DemonstrationError, Demonstrations


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
    if path.is_dir():
        raise DemonstrationError(f"{path}: is a directory, not a file of demonstrations")
    if path.suffix == ".npz":
        if action_scale not in (None, 1.0):
            raise DemonstrationError(
                f"{path}: an .npz set is stored in the environment's units: no action_scale"
            )
        return load_npz(path)
    return load_released(
        path, conf_path, action_scale, observation_size=observation_size, action_size=action_size
    )
