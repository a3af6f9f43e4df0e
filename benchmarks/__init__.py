"""Benchmarks behind every speed, memory or accuracy claim in avard.

Each ``bench_*.py`` module here has ``main(argv) -> int`` and prints a table whose ratios are
against a reference measured in the same run. ``python -m benchmarks`` lists them;
``python -m benchmarks NAME [args]`` runs one.
"""
