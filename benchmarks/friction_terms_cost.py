"""Cost of the friction-torque article's viscous and differential friction terms on the hot path (``Model.rhs``).

For each mechanism, the dynamic level's right-hand side (torque and speed drive, carriers at
equilibrium, 50 rad/s, 1 kN) is timed with the Coulomb law only (µ_1 = µ_3 = 0) and with all
three terms (the friction-torque article's values: µ_1 = 0.001 N·s/m, n_t = 10, µ_3 = 1e-6 m), one after the other
in one run (best of 7 repeats of 20 000 calls each; on a shared machine compare the ratios).  Prints µs per call and the ratio, measured
in this run, on this machine.

Run: ``python benchmarks/friction_terms_cost.py`` (about 20 s).
"""

from __future__ import annotations

import timeit

from prsm_fmu import presets
from prsm_fmu.models import make_model

CALLS = 20_000
REPEATS = 7


def rhs_cost(params, drive: str) -> float:
    """Best time of one ``rhs`` call [s] at 50 rad/s, 1 kN, carriers at equilibrium."""
    model = make_model(params, "dynamic", drive)
    x = model.initial_state((0.0, 0.0), screw_speed=50.0, carrier_ratio=None)
    u = (5.0, 1000.0) if drive == "torque" else (10.0, 1000.0)
    return min(timeit.repeat(lambda: model.rhs(0.0, x, u), number=CALLS, repeat=REPEATS)) / CALLS


def main() -> None:
    for name in ("friction_single_stage", "li2021_two_stage"):
        base = presets.load(name)
        coulomb = base.with_changes(mu_viscous=0.0, mu_differential=0.0)
        terms = coulomb.with_changes(mu_viscous=0.001, mu_differential=1e-6)
        for k in range(1, terms.n_stages + 1):
            terms = terms.with_stage(k, threads_per_roller=10)
        for drive in ("torque", "speed"):
            t_c = rhs_cost(coulomb, drive)
            t_t = rhs_cost(terms, drive)
            print(f"{name:22s} {drive:6s} rhs: Coulomb only {t_c * 1e6:6.2f} us, "
                  f"+ viscous + differential {t_t * 1e6:6.2f} us, ratio {t_t / t_c:.2f}")


if __name__ == "__main__":
    main()
