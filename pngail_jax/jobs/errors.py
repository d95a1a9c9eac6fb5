"""``RunError``: a job refused or stopped, for a reason its one-line message names."""

from __future__ import annotations

import contextlib

from pngail_jax.storage.outputs import OutputRefused, RunLocked


class RunError(Exception):
    """A run refused or stopped, for a reason its one-line message names (no traceback
    needed: a bad input, a changed file, a full disk)."""


@contextlib.contextmanager
def refusals():
    """Raises a refused output claim (``pngail_jax.storage.outputs.OutputRefused``) as a
    ``RunError`` with the same line (a held lock: ``cannot run: ...``)."""
    try:
        yield
    except RunLocked as error:
        raise RunError(f"cannot run: {error}") from None
    except OutputRefused as error:
        raise RunError(str(error)) from None
