"""What a run keeps on disk: SHA-256 records, atomic writes and seals (``integrity``), the
output contract (``outputs``: which program owns a folder, the claim and the lock),
checkpoints and saved policies (``checkpoint``) and JAX's compilation cache
(``compilation``)."""
