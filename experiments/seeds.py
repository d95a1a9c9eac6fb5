"""``python -m experiments.seeds`` from a checkout: runs pngail_jax.programs.seeds
(installed as the command ``pngail-seeds``)."""

from pngail_jax.programs.seeds import main

if __name__ == "__main__":
    main()
