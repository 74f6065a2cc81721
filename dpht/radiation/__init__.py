"""Radiation: the Monte Carlo ray tracer, packed-bed generation, RDF table building and the
radiation-model study of the DPHT paper's Section 4."""
