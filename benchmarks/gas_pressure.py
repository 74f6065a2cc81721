"""Effect of the gas pressure on the gas-gap conductances (dpht.closures.htc, temperature jump).

Prints, for air between particles of conductivity 2 W/(m K) (the DPHT paper's Figures 4 and 6; solid
fraction 0.6 for the cone radius, Eq. 13), the PFP conductance at contact (d = 2R) and at 1.1
diameters (a surface gap of 0.1 d) and the PFW conductance at contact (d_iw = R) and at the same
surface gap (d_iw = R + 0.1 d), at 300 and 1000 K, in the continuum (the paper's model) and at
1 atm, 1000 Pa and 10 Pa, each with its change against the continuum; and the temperature-jump
distances of air at the default accommodation coefficient (0.84).

    python benchmarks/gas_pressure.py                       # 1 mm and 100 um particles
    python benchmarks/gas_pressure.py --diameters 2e-3      # other diameters (m)
    python benchmarks/gas_pressure.py --tiny                # 1 mm only (the tests)
"""

from __future__ import annotations

import argparse

from dpht.closures import gas, htc

PRESSURES = ("continuum", gas.ATMOSPHERE, 1000.0, 10.0)
TEMPERATURES = (300.0, 1000.0)


def rows(diameter: float):
    """(kind, where, T, {pressure: HTC W/K}) for one particle diameter (m)."""
    radius = diameter / 2
    params = dict(radius=radius, k_solid=2.0, solid_fraction=0.6)
    places = {"pfp": {"contact": 2 * radius, "1.1 d": 1.1 * diameter},
              "pfw": {"contact": radius, "gap 0.1 d": radius + 0.1 * diameter}}
    for kind, where in places.items():
        for label, distance in where.items():
            for temperature in TEMPERATURES:
                values = {p: float(getattr(htc, kind)(distance, temperature, **params, pressure=p)) for p in PRESSURES}
                yield kind, label, temperature, values


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--diameters", type=float, nargs="+", default=[1e-3, 1e-4], help="particle diameters, m")
    parser.add_argument("--tiny", action="store_true", help="1 mm particles only (the tests)")
    args = parser.parse_args(argv)
    if args.tiny:
        args.diameters = [1e-3]
    for temperature in TEMPERATURES:
        jumps = ", ".join(f"{p:g} Pa: {gas.jump_distance('air', temperature, p, 0.84) * 1e6:.3g} um"
                          for p in PRESSURES[1:])  # fmt: skip
        print(f"air, jump distance at {temperature:g} K (a = 0.84): {jumps}")
    header = " | ".join(f"{p if isinstance(p, str) else f'{p:g} Pa':>20s}" for p in PRESSURES)
    for diameter in args.diameters:
        print(f"\nd = {diameter * 1e3:g} mm: HTC in W/K (change against the continuum)")
        print(f"{'':22s} {header}")
        for kind, label, temperature, values in rows(diameter):
            continuum = values["continuum"]
            cells = [f"{continuum:20.4e}"] + [f"{v:11.4e} ({v / continuum - 1:+6.1%})" for p, v in values.items()
                                              if p != "continuum"]  # fmt: skip
            print(f"{kind} {label:9s} {temperature:6.0f} K  " + " | ".join(cells))


if __name__ == "__main__":
    main()
