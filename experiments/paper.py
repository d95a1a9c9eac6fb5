"""``python -m experiments.paper`` from a checkout: runs pngail_jax.programs.paper
(installed as the command ``pngail-paper``)."""

from pngail_jax.programs.paper import main

if __name__ == "__main__":
    main()
