"""The demonstrations part of a run's config, as plain data: which files a run reads its
demonstrations from, in what units, and the normalised return's ends, each checked once for
every job that reads demonstrations (the sweep's ``RunConfig``, the offline job's
``OfflineRunConfig``). ``jobs.demonstrations`` reads and makes what it names. Imports no
JAX."""

from __future__ import annotations

import dataclasses

from pngail_jax.config.validation import fail, real

# A Minari dataset's id follows it: demos.minari's prefix, spelled here too because demos/
# imports no config part but the plain tables (tests/test_layers.py).
MINARI_PREFIX = "minari:"


@dataclasses.dataclass(frozen=True)
class DemonstrationsConfig:
    """``demos``: a ``*_mixture.npy`` (authors' layout), an .npz, or ``"minari:<id>"``; None:
    made with ``jobs.make_demos`` and cached. ``conf``: the confidence file (default: the
    mixture's sibling). ``confidence_field``: a Minari dataset's per-episode field holding
    confidences. ``action_scale`` multiplies stored actions (None: an authors' file's known
    scale, else 1). ``random_return`` / ``optimal_return``: the normalised return's ends,
    (R - random) / (optimal - random) (None: the demonstrations' own; an optimal return
    alone: the random one measured). The checks name the field (``ConfigError``)."""

    demos: str | None = None
    conf: str | None = None
    confidence_field: str | None = None
    action_scale: float | None = None
    random_return: float | None = None
    optimal_return: float | None = None

    def __post_init__(self):
        for name in ("demos", "conf", "confidence_field"):
            value = getattr(self, name)
            if value is not None and (not isinstance(value, str) or not value):
                fail(name, f"must be a non-empty string or None, got {value!r}")
        if self.action_scale is not None:
            self._set("action_scale", real("action_scale", self.action_scale))
            if self.action_scale <= 0:
                fail("action_scale", f"must be finite and positive, got {self.action_scale!r}")
        for name in ("random_return", "optimal_return"):
            if getattr(self, name) is not None:
                self._set(name, real(name, getattr(self, name), "be a finite number"))
        self._check_returns()
        self._check_companions()

    def _set(self, name: str, value) -> None:
        object.__setattr__(self, name, value)  # frozen: a number stored as a Python float

    def _check_returns(self) -> None:
        if self.random_return is not None and self.optimal_return is None:
            fail("random_return", "needs optimal_return (the normalised return's other end)")
        if None not in (self.random_return, self.optimal_return) and not (
            self.optimal_return > self.random_return
        ):
            fail(
                "optimal_return",
                f"({self.optimal_return}) must be above random_return ({self.random_return})",
            )

    def _check_companions(self) -> None:
        """The fields that go with a kind of demonstrations file."""
        if self.conf is not None and self.demos is None:
            fail("conf", ": a confidence file needs demos (made demonstrations carry their own)")
        is_minari = self.demos is not None and self.demos.startswith(MINARI_PREFIX)
        if self.confidence_field is not None and not is_minari:
            fail(
                "confidence_field",
                "reads a Minari dataset's episode metadata: demos minari:<id>",
            )
        if (
            self.demos is not None
            and self.demos.endswith(".npz")
            and (self.conf is not None or self.action_scale not in (None, 1.0))
        ):
            fail(
                "demos", ": an .npz set carries its confidences and units: no conf or action_scale"
            )


DEMONSTRATION_FIELDS = tuple(field.name for field in dataclasses.fields(DemonstrationsConfig))


def demonstrations_part(config) -> DemonstrationsConfig:
    """The demonstrations part of a job's config that holds its fields flat (``RunConfig``,
    ``OfflineRunConfig``, whose config.json keep them so); a field it lacks is None."""
    return DemonstrationsConfig(
        **{name: getattr(config, name, None) for name in DEMONSTRATION_FIELDS}
    )
