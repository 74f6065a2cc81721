"""Closures the thermal kernels read: contact conduction and softening (DPHT paper Eqs. 2-7), gas
conductivity and the gas-gap HTC tables (Eqs. 8-24), specific heat as enthalpy tables, and the
radiation distribution factor (RDF) table format (Eqs. 25-26)."""
