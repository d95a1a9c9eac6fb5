"""Deprecated: ``pngail_jax.train`` is now ``pngail_jax.adversarial`` (and ``Hyperparams`` is
``AdversarialHyperparams``). This module re-exports them for one minor version."""

import warnings

from pngail_jax.adversarial import *  # noqa: F403
from pngail_jax.adversarial import AdversarialHyperparams

Hyperparams = AdversarialHyperparams

warnings.warn(
    "pngail_jax.train is now pngail_jax.adversarial (Hyperparams: AdversarialHyperparams)",
    DeprecationWarning,
    stacklevel=2,
)
