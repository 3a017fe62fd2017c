"""Benchmark suites run by ``millflow bench SUITE [--json] [--quick]``.

Each module of this package is a suite (``core``, ``mill``, ``flowsheet``, ``fit``)
exposing ``DESCRIPTION`` (str) and ``run(quick: bool = False) -> list[dict]``; every
row has ``case``, ``method``, ``runtime_s`` and, where they apply, ``max_abs_error``,
``mass_balance_error`` and ``ratio_vs_baseline`` (docs/CONTRACTS.md, "Benchmarks").
A suite may also expose ``format_table(rows) -> str`` for the human-readable output.
"""
