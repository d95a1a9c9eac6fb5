"""Deprecated: ``pngail_jax.train`` is now ``pngail_jax.adversarial.trainer`` (and
``Hyperparams`` is ``AdversarialHyperparams``). This module re-exports them until 0.3 and is
removed then, with ``pngail_jax.runner``."""

import warnings

from pngail_jax.adversarial.trainer import *  # noqa: F403
from pngail_jax.adversarial.trainer import AdversarialHyperparams

Hyperparams = AdversarialHyperparams

warnings.warn(
    "pngail_jax.train is now pngail_jax.adversarial.trainer (Hyperparams: AdversarialHyperparams); "
    "pngail_jax.train goes in 0.3",
    DeprecationWarning,
    stacklevel=2,
)
