"""The confidence classifier's static settings (``ClassifierConfig``), as plain data: part of
a run's config (``RunConfig.classifier``) that imports no JAX. ``pngail_jax.confidence``
trains the classifier these describe (and re-exports the name)."""

from __future__ import annotations

import dataclasses

from pngail_jax.config import validation

# BSC's clip eps (eq. 13) where a task does not set its own (config.task.TASK_BSC_EPS).
DEFAULT_BSC_EPS = 0.01


@dataclasses.dataclass(frozen=True)
class ClassifierConfig:
    """Static settings. Defaults: the reference code (25,000 steps, each on 1 labelled row and
    int(n_u / n_c) unlabelled rows: 4 at label ratio 0.2, 9 at 0.1, 19 at 0.05, 32 at 0.03);
    the paper's Walker2d setting is 50,000 steps and eps 0.05.

    ``unlabelled_batch_size`` None follows the authors: ``labelled_batch_size * (n_u // n_c)``
    rows per step, computed per cell from its split (so one grid holds several label ratios),
    in a batch of static width ``max_unlabelled_batch_size`` whose last rows are masked out.
    An integer fixes the number of rows for every label ratio (the width is then that number).
    """

    num_steps: int = 25_000
    labelled_batch_size: int = 1
    unlabelled_batch_size: int | None = None
    max_unlabelled_batch_size: int = 32
    learning_rate: float = 3e-4
    hidden_sizes: tuple[int, ...] = (40, 40)
    dropout_rate: float = 0.5

    def __post_init__(self):
        for name in (
            "num_steps", "labelled_batch_size", "unlabelled_batch_size",
            "max_unlabelled_batch_size",
        ):  # fmt: skip
            value = getattr(self, name)
            if value is None and name == "unlabelled_batch_size":
                continue
            if not isinstance(value, int) or value < 1:  # RunConfig also refuses a bool
                validation.fail(
                    name, f"must be a positive integer, got {value!r}",
                    name=f"ClassifierConfig.{name}",
                )  # fmt: skip

    @property
    def unlabelled_batch_width(self) -> int:
        """The static number of unlabelled rows drawn per step (some masked when None)."""
        if self.unlabelled_batch_size is None:
            return self.max_unlabelled_batch_size
        return self.unlabelled_batch_size

    def unlabelled_rows_per_step(self, num_rows: int, num_labelled: int) -> int:
        """Host-side: the unlabelled rows a step uses for a split of ``num_rows`` rows with
        ``num_labelled`` labelled (before the cap of ``unlabelled_batch_width``)."""
        if self.unlabelled_batch_size is not None:
            return self.unlabelled_batch_size
        return self.labelled_batch_size * max((num_rows - num_labelled) // num_labelled, 1)
