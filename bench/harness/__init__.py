"""The yardsticks of tests and benchmarks, kept out of the extension: Cycles reference bakes
(``cycles``), our per-vertex results in their shape (``compare``) and the error measures the manual
quotes (``metrics``). Importable as ``harness`` with ``bench/`` on the path (tests/conftest.py
puts it there; the benchmark scripts run from it)."""
