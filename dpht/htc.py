"""Public API: the gas-gap heat transfer coefficients of the DPHT paper (Eqs. 8-13, 18-20).

``dpht.htc.pfp(distance, temperature, radius=..., k_solid=..., solid_fraction=..., gas=..., pressure=...,
accommodation=...)`` and ``dpht.htc.pfw(...)`` give the particle-fluid-particle and particle-fluid-wall
conductances in W/K, at the gas pressure ``pressure`` (Pa, default 1 atm, with the temperature jump of a
rarefied gas; ``"continuum"`` for the paper's model) (documented in README). The implementation and the
table format live in :mod:`dpht.closures.htc`.
"""

from dpht.closures.htc import pfp, pfw

__all__ = ["pfp", "pfw"]
