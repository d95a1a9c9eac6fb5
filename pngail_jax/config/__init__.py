"""The parts a run is made of: the field checks every config shares (``validation``), the
methods' presets and names as plain data (``presets``), the authors' files as data
(``released_files``), the per-environment settings (``settings``), a sweep's ``RunConfig``
and its checks (``run_config``, ``run_config_checks``) and what a saved ``config.json``
keeps around it (``saved``). Nothing is imported here: ``validation``, ``presets`` and
``released_files`` import no JAX."""
