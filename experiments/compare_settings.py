"""``python -m experiments.compare_settings`` from a checkout: runs
pngail_jax.programs.compare_settings (installed as the command ``pngail-compare-settings``)."""

from pngail_jax.programs.compare_settings import main

if __name__ == "__main__":
    main()
