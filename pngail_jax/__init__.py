"""pngail-jax: PN-GAIL and its baselines for imitation from imperfect demonstrations, in JAX."""

__version__ = "0.1.0"
