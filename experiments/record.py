"""``python -m experiments.record`` from a checkout: runs pngail_jax.programs.record
(installed as the command ``pngail-record``)."""

from pngail_jax.programs.record import main

if __name__ == "__main__":
    main()
