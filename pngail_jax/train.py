"""Deprecated: ``pngail_jax.train`` is now ``pngail_jax.adversarial`` (and ``Hyperparams`` is
``AdversarialHyperparams``). This module re-exports them until 0.3 and is removed
then, with ``pngail_jax.runner``."""

import warnings

from pngail_jax.adversarial import *  # noqa: F403
from pngail_jax.adversarial import AdversarialHyperparams

Hyperparams = AdversarialHyperparams

warnings.warn(
    "pngail_jax.train is now pngail_jax.adversarial (Hyperparams: AdversarialHyperparams); "
    "pngail_jax.train goes in 0.3",
    DeprecationWarning,
    stacklevel=2,
)
