"""``python -m experiments.classify`` from a checkout: runs pngail_jax.programs.classify
(installed as the command ``pngail-classify``)."""

from pngail_jax.programs.classify import main

if __name__ == "__main__":
    main()
