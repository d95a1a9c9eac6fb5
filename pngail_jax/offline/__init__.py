"""The offline family: its losses (``losses``: DWBC, ISW-BC, ILID), ILID's discriminators
and selection (``ilid``) and the trainer with its specs and presets (``trainer``:
``OfflineTrainer``, ``OfflineSpec``)."""
