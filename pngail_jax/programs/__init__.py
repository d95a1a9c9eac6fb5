"""The command-line programs: each is its flags and calls into the library.

From a checkout they run as ``python -m experiments.<program>`` (the one-line entry points
in ``experiments/``); installed, as the commands of ``commands`` (``pngail-sweep``,
``pngail-paper``, ...). ``cli`` holds the flag helpers they share.
"""
