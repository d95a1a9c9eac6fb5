"""pngail-jax: PN-GAIL and its baselines for imitation from imperfect demonstrations, in JAX."""

__version__ = "0.1.0"


def load_policy(directory, seed=None, verbose=True):
    """Loads a saved policy as ``policy(obs) -> action``; see ``pngail_jax.checkpoint``."""
    from pngail_jax.checkpoint import load_policy as _load_policy

    return _load_policy(directory, seed=seed, verbose=verbose)
