"""The output part of a run's config, as plain data: the logging backends a run may feed
once per chunk (``RunConfig.log``; ``pngail_jax.analysis.tracking`` runs them), each with the
module it needs. Imports nothing."""

from __future__ import annotations

# Each backend and the module it needs.
BACKEND_MODULES = {"tensorboard": "tensorboardX", "wandb": "wandb"}
LOG_BACKENDS = tuple(BACKEND_MODULES)
