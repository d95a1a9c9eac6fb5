"""``python -m experiments.sweep`` from a checkout: runs pngail_jax.programs.sweep
(installed as the command ``pngail-sweep``)."""

from pngail_jax.programs.sweep import main

if __name__ == "__main__":
    main()
