"""Field checks shared by every config (``RunConfig``, ``OfflineRunConfig``, ``RunSettings``,
the classifier's).

Each check returns the value in its stored type (a NumPy integer as a Python ``int``, an
``int`` in a float field as a ``float``) or raises ``ConfigError`` naming the field. A
``ConfigError`` carries the field's path in ``RunConfig`` (``"seeds"``,
``"settings.num_envs"``, ``"classifier.num_steps"``) apart from the reason, so a program
names the field in its own words (the sweep: by its flag, ``pngail_jax.programs.flags``)
without rewriting the text.
"""

from __future__ import annotations

import math
import numbers
from typing import NoReturn


class ConfigError(ValueError):
    """A bad config value: ``field`` (its path in ``RunConfig``, dotted for nested configs)
    and ``reason`` (the sentence after the field's name: ``"must be a positive integer, got
    0"``, or ``": ..."`` for a reason that reads as a note on the field).

    ``str()`` reads ``"<name> <reason>"``, with ``name`` the field's path unless given
    (``"label ratios"``, ``"ClassifierConfig.num_steps"``).
    """

    def __init__(self, field: str, reason: str, *, name: str | None = None):
        self.field = field
        self.reason = reason
        self.name = name or field
        super().__init__(self.named(self.name))

    def named(self, name: str) -> str:
        """The message with the field called ``name`` (a flag, say)."""
        return f"{name}{'' if self.reason.startswith(':') else ' '}{self.reason}"

    def nested(self, parent: str) -> ConfigError:
        """The same error one level down, under ``parent`` (``"settings"``): the field's path
        gains the prefix, the name stays."""
        return ConfigError(f"{parent}.{self.field}", self.reason, name=self.name)


def fail(field: str, reason: str, *, name: str | None = None) -> NoReturn:
    raise ConfigError(field, reason, name=name)


def integer(field: str, value, minimum: int, below: int | None = None, *, name=None) -> int:
    """``value`` as a Python int when it is an integer (not a bool) in ``[minimum, below)``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, numbers.Integral)
        or value < minimum
        or (below is not None and value >= below)
    ):
        if below is not None:
            power = below.bit_length() - 1
            limit = f"2**{power}" if below == 2**power else str(below)
            what = f"an integer in [{minimum}, {limit})"
        else:
            what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        fail(field, f"must be {what}, got {value!r}", name=name)
    return int(value)


def real(field: str, value, requirement: str = "be finite and positive", *, name=None) -> float:
    """``value`` as a Python float when it is a finite real number (not a bool); else
    ConfigError "``field`` must ``requirement``"."""
    number = math.nan
    if not isinstance(value, bool) and isinstance(value, numbers.Real):
        try:
            number = float(value)
        except OverflowError:  # an int beyond float's range
            pass
    if not math.isfinite(number):
        fail(field, f"must {requirement}, got {value!r}", name=name)
    return number


# A range as (requirement, test): what a message says a value must do, and the test of it.
# The per-cell data settings' ranges are written here once, for the sweep's axes (label
# ratios, noise stds) and the offline program's single values (label ratio, noise std).
OPEN_UNIT_INTERVAL = ("lie in (0, 1)", lambda value: 0 < value < 1)
LABEL_RATIO_RANGE = OPEN_UNIT_INTERVAL
NOISE_STD_RANGE = ("be finite and >= 0", lambda value: value >= 0)


def within(field: str, value, rule: tuple, *, name=None) -> float:
    """``value`` as a Python float when it is a finite real number (not a bool) meeting
    ``rule`` (requirement, test: ``LABEL_RATIO_RANGE``, say); else ConfigError "``field``
    must ``requirement``"."""
    requirement, valid = rule
    number = real(field, value, requirement, name=name)
    if not valid(number):
        fail(field, f"must {requirement}, got {value!r}", name=name)
    return number


def float_axis(field: str, values: tuple, requirement: str, valid, *, name=None):
    """A grid axis (label ratios, noise stds): finite floats meeting ``valid``, not empty,
    none repeated."""
    if not values:
        fail(field, "must not be empty", name=name)
    floats = tuple(real(field, value, requirement, name=name) for value in values)
    if not all(valid(value) for value in floats):
        fail(field, f"must {requirement}, got {list(values)}", name=name)
    if len(set(floats)) != len(floats):
        fail(field, f"must not repeat, got {list(values)}", name=name)
    return floats


def layer_sizes(field: str, values, *, name=None) -> tuple[int, ...]:
    """Hidden-layer widths: a tuple of positive ints (empty: no hidden layer)."""
    values = tuple(values) if isinstance(values, list | tuple) else (values,)
    if not all(
        isinstance(size, numbers.Integral) and not isinstance(size, bool) and size >= 1
        for size in values
    ):
        fail(field, f"must be positive integers (layer widths), got {list(values)}", name=name)
    return tuple(int(size) for size in values)


def is_among(name, known) -> bool:
    """Whether ``name`` is one of the strings ``known`` (False for a list or dict, which a
    membership test of a dict would raise TypeError on)."""
    return isinstance(name, str) and name in known
