"""The checks of a ``RunConfig`` that read its fields together, run when a config is made
(``RunConfig.__post_init__``, after each field is normalised to its type): the names each
field must be among (the methods: registered or importable presets, each once; the log
backends; the grid axes' values on the run's learner and methods). The checks every job's
config shares are its parts' (``config.training``, ``config.demonstrations``,
``config.learner``). Each failure is a ``ConfigError`` naming the field (the command line
names its flag)."""

from __future__ import annotations

import dataclasses

from pngail_jax.config.grid_axes import METHOD_AXES
from pngail_jax.config.learner import check_cell_value
from pngail_jax.config.methods import check_preset, resolve
from pngail_jax.config.output import LOG_BACKENDS
from pngail_jax.config.presets import ALL_METHOD_NAMES, PRESETS
from pngail_jax.config.validation import fail, is_among


def check_names(config) -> None:
    """The names each field must be among: methods, log backends, the grid axes' fields
    (the learner's are its part's own: ``config.learner.LearnerConfig``)."""
    if not config.methods:
        fail(
            "methods",
            f"must name at least one method; available: {', '.join(ALL_METHOD_NAMES)}",
        )
    unknown = [
        name for name in config.methods
        if not isinstance(name, str) or (":" not in name and name not in PRESETS)
    ]  # fmt: skip
    if unknown:
        fail(
            "methods",
            f": unknown method(s) {unknown}; available: {', '.join(PRESETS)}, or "
            "package.module:preset",
        )
    for name in config.methods:  # a registered name, or package.module:preset, imported
        try:
            resolve(name)
        except ValueError as error:
            fail("methods", f": {error}")
    if len(set(config.methods)) != len(config.methods):
        fail("methods", f"must not repeat, got {list(config.methods)}")
    bad_backends = [name for name in config.log if not is_among(name, LOG_BACKENDS)]
    if bad_backends:
        fail(
            "log",
            f": unknown log backend(s) {bad_backends}; available: {', '.join(LOG_BACKENDS)}",
        )
    if len(set(config.log)) != len(config.log):
        fail("log", f"backends must not repeat, got {list(config.log)}")
    if config.baseline is not None and config.baseline not in config.methods:
        fail("baseline", f"must be one of the run's methods {list(config.methods)}, got "
             f"{config.baseline!r}")  # fmt: skip
    for field, values in config.grid_axes:  # a hyperparameter's range
        if field in METHOD_AXES:
            continue
        for value in values:
            try:
                check_cell_value(config.learner.name, field, value)
            except ValueError as error:
                fail("grid_axes", f": {field}={value:g}: {error}")
    for name in config.methods:  # every value of a coefficient axis, on every method
        for field, values in config.grid_axes:
            if field not in METHOD_AXES:
                continue
            preset = resolve(name)
            for value in values:
                changed = {**preset.coefficients, field: value}
                try:
                    check_preset(name, dataclasses.replace(preset, coefficients=changed))
                except ValueError as error:
                    fail("grid_axes", f": {field}={value:g} on {error}")
