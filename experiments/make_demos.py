"""``python -m experiments.make_demos`` from a checkout: runs pngail_jax.programs.make_demos
(installed as the command ``pngail-make-demos``)."""

from pngail_jax.programs.make_demos import main

if __name__ == "__main__":
    main()
