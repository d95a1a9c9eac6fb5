"""The adversarial family as a ``grid.MethodFamily``: ``ADVERSARIAL``.

Its methods are ``MethodSpec`` presets (``methods``: the paper's seven, the appendix
baselines', registered ones and ``package.module:preset``), its per-cell hyperparameters an
``AdversarialHyperparams`` (the policy learner's and the discriminator's), its compiled parts
the appendix baselines' training phases (``required_phases``), and a grid of any of its
methods is one program (a vmapped program of the phases every method of the grid needs).
"""

from __future__ import annotations

from collections.abc import Sequence

from pngail_jax.adversarial.methods import (
    ALL_METHOD_NAMES,
    MethodSpec,
    method_spec,
    required_phases,
    resolve,
)
from pngail_jax.adversarial.trainer import AdversarialHyperparams, AdversarialTrainer
from pngail_jax.config.grid_axes import HYPERPARAM_AXES, METHOD_AXES
from pngail_jax.grid import Cell, MethodFamily


def check_method(name: str) -> str:
    """``name``, once it resolves to a preset (built-in, registered, or
    ``package.module:preset``, which this imports and registers); ValueError otherwise."""
    resolve(name)
    return name


def spec(name: str, **overrides: float) -> MethodSpec:
    """The method ``name`` as a ``MethodSpec`` (float[] leaves), fields overridden."""
    return method_spec(name, **overrides)


def hyperparams(cell: Cell, **values) -> AdversarialHyperparams:
    """The cell's ``AdversarialHyperparams`` (float[] leaves): its label ratio and noise, and
    ``values``, ``AdversarialHyperparams.create`` keywords (the learner's among them)."""
    return AdversarialHyperparams.create(
        label_ratio=cell.label_ratio, noise_std=cell.noise_std, **values
    )


def program_groups(methods: Sequence[str]) -> list[tuple[str, ...]]:
    """One program for every method: the trainer compiles the phases any of them needs
    (``required_phases``) and each cell's spec selects what it reads."""
    for name in methods:
        check_method(name)
    return [tuple(methods)] if methods else []


ADVERSARIAL = MethodFamily(
    name="adversarial",
    method_names=ALL_METHOD_NAMES,
    check_method=check_method,
    spec=spec,
    spec_axes=METHOD_AXES,
    hyperparam_axes=HYPERPARAM_AXES,
    hyperparams=hyperparams,
    parts=required_phases,
    program_groups=program_groups,
    trainer=AdversarialTrainer,
)
