"""``python -m experiments.offline`` from a checkout: runs pngail_jax.programs.offline
(installed as the command ``pngail-offline``)."""

from pngail_jax.programs.offline import main

if __name__ == "__main__":
    main()
