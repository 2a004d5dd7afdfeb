"""Benchmarks are scripts (``python tests/benchmarks/bench_modbus_codec.py``), never collected."""

collect_ignore_glob = ["bench_*.py"]
