"""pngail-jax: PN-GAIL and its baselines for imitation from imperfect demonstrations, in JAX.

The user's path, importable from here (each loaded on first use, so ``import pngail_jax``
stays fast): ``run`` / ``RunConfig`` / ``RunResult`` / ``RunError`` (a whole run with its
outputs, ``pngail_jax.jobs``), ``load_demonstrations``, the trainers (``AdversarialTrainer``,
``AdversarialConfig``), grids (``make_cells``, ``stack_cells``, ``Grid``), the method families
a grid stacks (``MethodFamily``; ``ADVERSARIAL``, ``OFFLINE``) and ``load_policy``.
"""

import importlib

__version__ = "0.1.0"

# name -> the module that defines it
_EXPORTS = {
    "run": "pngail_jax.jobs.sweep",
    "RunResult": "pngail_jax.jobs.results",
    "RunError": "pngail_jax.jobs.errors",
    "RunConfig": "pngail_jax.config.run_config",
    "load_demonstrations": "pngail_jax.demos",
    "AdversarialTrainer": "pngail_jax.adversarial.trainer",
    "AdversarialConfig": "pngail_jax.adversarial.trainer",
    "make_cells": "pngail_jax.grid",
    "stack_cells": "pngail_jax.grid",
    "Grid": "pngail_jax.grid",
    "MethodFamily": "pngail_jax.grid",
    "ADVERSARIAL": "pngail_jax.adversarial.family",
    "OFFLINE": "pngail_jax.offline.family",
}
__all__ = ["load_policy", *_EXPORTS]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'pngail_jax' has no attribute {name!r}")


def load_policy(directory, seed=None, verbose=True):
    """Loads a saved policy as ``policy(obs) -> action``; see ``pngail_jax.storage.checkpoint``."""
    from pngail_jax.storage.checkpoint import load_policy as _load_policy

    return _load_policy(directory, seed=seed, verbose=verbose)
