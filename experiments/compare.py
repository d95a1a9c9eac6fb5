"""``python -m experiments.compare`` from a checkout: runs pngail_jax.programs.compare
(installed as the command ``pngail-compare``)."""

from pngail_jax.programs.compare import main

if __name__ == "__main__":
    main()
