"""The offline family as a ``grid.MethodFamily``: ``OFFLINE``.

Its methods are ``OfflineSpec`` presets (``trainer.OFFLINE_PRESETS``: BC on the expert rows,
BC on every row, DWBC, ISW-BC, ILID, each also as ``<name>+bsc``), its per-cell
hyperparameters an ``OfflineHyperparams`` (the split's label ratio and noise), its compiled
parts the components its methods read (``required_components``), and a grid of its methods
is one program per set of components (``program_groups``), so no cell pays for a part only
another method reads.
"""

from __future__ import annotations

from pngail_jax.grid import Cell, MethodFamily
from pngail_jax.offline.trainer import (
    CLASSIFIED_SUFFIX,
    OFFLINE_METHOD_NAMES,
    OfflineHyperparams,
    OfflineSpec,
    OfflineTrainer,
    offline_spec,
    program_groups,
    required_components,
)


def check_method(name: str) -> str:
    """``name``, when it is an offline preset or ``<preset>+bsc``; ValueError otherwise."""
    required_components([name])
    return name


def spec(name: str, **overrides: float) -> OfflineSpec:
    """The method ``name`` as an ``OfflineSpec`` (float[] leaves), fields overridden."""
    return offline_spec(name, **overrides)


def hyperparams(cell: Cell, **values) -> OfflineHyperparams:
    """The cell's ``OfflineHyperparams`` (float[] leaves): its label ratio and noise (the
    offline family shares no other per-cell value: ``values`` must be empty)."""
    return OfflineHyperparams.create(cell.label_ratio, cell.noise_std, **values)


OFFLINE = MethodFamily(
    name="offline",
    method_names=(
        *OFFLINE_METHOD_NAMES,
        *(f"{name}{CLASSIFIED_SUFFIX}" for name in OFFLINE_METHOD_NAMES),
    ),
    check_method=check_method,
    spec=spec,
    spec_axes=(),  # an offline grid varies its methods, seeds, label ratio and noise only
    hyperparam_axes=(),
    hyperparams=hyperparams,
    parts=required_components,
    program_groups=program_groups,
    trainer=OfflineTrainer,
)
