"""``python -m experiments.agreement`` from a checkout: runs pngail_jax.programs.agreement
(installed as the command ``pngail-agreement``)."""

from pngail_jax.programs.agreement import main

if __name__ == "__main__":
    main()
