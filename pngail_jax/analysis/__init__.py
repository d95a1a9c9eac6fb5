"""Reading run folders and records: a run's files (``runs``), its report and statistics
(``report``, ``stats``), comparisons across runs (``compare``), committed records and their
tables (``run_records``, ``record_tables``), figures (``plots``) and the optional experiment
trackers a sweep logs to (``tracking``). It reads and writes files only: importing this
package, or any module of it, imports no JAX (tests/test_layers.py checks each)."""
