"""Verification: the harness of ``python -m dpht verify`` and the oracles the tests share.

``harness`` registers and runs named cases, ``cases/`` holds one module of cases per physical
model, ``reference`` is the brute-force (all pairs, every wall element) evaluation of the heat
rates and ``scenes`` builds the small synthetic scenes the cases, tests and benchmarks use. Nothing
in the workflow imports this package.
"""
