"""The documented ``python -m experiments.<program>`` commands, from a checkout.

Each module here is an entry point of one line: the programs live in ``pngail_jax.programs``
and are installed as console scripts (``pngail-sweep``, ``pngail-paper``, ...). This folder
is not installed, so no top-level ``experiments`` package is put into a user's environment.
"""
