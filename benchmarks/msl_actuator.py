"""The MSL example ActuatorWithNoise rebuilt with the PRSM FMU, against its published reference.

Prints the rod position at 1.0, 1.5, 2.0, 3.0 s, the peak and its time, the final value, the
overshoot and the 2 % settling time of the scene ``msl_actuator_with_noise`` beside MSL's
published reference results (tests/data/msl_actuator_with_noise.csv, MSL 4.1.0 and 4.0.0), for

* the scene as written (noise seed 1),
* the same scene without noise,
* ``--seeds N`` further noise realisations (seeds 2..N+1): the spread a noise realisation alone
  causes, which is what the comparison's tolerance is built from (docs/ema.md §10),
* the scene at h/5: the co-simulation's own error;

and last the scene's largest distance to MSL 4.1.0 over the compared rod positions.

::

    python benchmarks/msl_actuator.py                 # ≈ 1 min with the FMU
    python benchmarks/msl_actuator.py --prsm python --seeds 8
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from system_models.analysis import step_metrics  # noqa: E402
from system_models.run import run_scene  # noqa: E402
from system_models.scenes import load_scene  # noqa: E402

POINTS = (1.0, 1.5, 2.0, 3.0)
DATA = ROOT / "tests" / "data" / "msl_actuator_with_noise.csv"


def reference() -> dict[str, dict[str, float]]:
    """The published numbers: {column: {quantity: value}}."""
    with open(DATA, encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    cols = [c for c in rows[0] if c.startswith("msl_")]
    return {c: {r["quantity"]: float(r[c]) for r in rows} for c in cols}


def figures(time: np.ndarray, x: np.ndarray) -> dict[str, float]:
    """The compared figures of a rod-position trace [m] on the time grid [s]."""
    out = {f"rod_position_at_{t}s": float(np.interp(t, time, x)) for t in POINTS}
    k = int(np.argmax(x))
    out.update(rod_position_final_8_0s=float(x[-1]), rod_position_peak=float(x[k]),
               rod_position_peak_time=float(time[k]))
    m = step_metrics(time, x, 0.0, float(x[-1]), 0.5, band=0.02)
    out.update(settling_time_2pct_after_0_5s=m["settling_time"],
               overshoot=(float(x[k]) - float(x[-1])) / float(x[-1]))
    return out


def variant(scene, seed: int | None):
    c = dict(scene.controller)
    if seed is None:
        c.pop("sensor", None)
    else:
        s = dict(c["sensor"])
        s["noise"] = dict(s["noise"], seed=seed)
        c["sensor"] = s
    return dataclasses.replace(scene, controller=c)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--prsm", choices=["fmu", "python"], default="fmu")
    ap.add_argument("--fmu", default=str(ROOT / "dist" / "PRSM1.fmu"))
    ap.add_argument("--seeds", type=int, default=4, help="extra noise realisations")
    args = ap.parse_args(argv)
    fmu = None
    if args.prsm == "fmu":
        from system_models.fmu import ensure_fmu

        fmu = ensure_fmu(args.fmu)
    scene = load_scene("msl_actuator_with_noise")
    runs = {}

    def go(label, sc, **kw):
        r = run_scene(sc, prsm=args.prsm, fmu_path=fmu, **kw).result
        runs[label] = figures(r.time, r["prsm.rod_position"])
        runs[label]["phi_rel_final"] = float(r["gear.phi_rel"][-1])
        print(f"  ran {label}: {r.stats['macro_steps']} steps in {r.stats['wall_time']:.1f} s",
              file=sys.stderr)

    go("scene (seed 1)", scene)
    go("no noise", variant(scene, None))
    go("no noise, h/5", variant(scene, None), step=scene.step / 5)
    for s in range(2, 2 + args.seeds):
        go(f"seed {s}", variant(scene, s))
    ref = reference()
    keys = [f"rod_position_at_{t}s" for t in POINTS] + ["rod_position_final_8_0s",
                                                        "rod_position_peak"]
    ref_keys = {k: k.replace("8_0s", "8.0s") for k in keys}
    print("| figure | " + " | ".join(list(ref) + list(runs)) + " |")
    print("|---" * (1 + len(ref) + len(runs)) + "|")
    for k in keys:
        cells = [f"{1e3 * ref[c][ref_keys[k]]:.4f}" for c in ref] + \
                [f"{1e3 * runs[r][k]:.4f}" for r in runs]
        print(f"| {k} [mm] | " + " | ".join(cells) + " |")
    for k, rk, scale, unit in (("rod_position_peak_time", "rod_position_peak_time", 1, "s"),
                               ("settling_time_2pct_after_0_5s", "settling_time_2pct_after_0.5s", 1, "s"),
                               ("phi_rel_final", "gearbox_phi_rel_final", 1e3, "mrad")):
        cells = [f"{scale * ref[c][rk]:.4f}" for c in ref] + [f"{scale * runs[r][k]:.4f}" for r in runs]
        print(f"| {k} [{unit}] | " + " | ".join(cells) + " |")
    cells = [f"{100 * (ref[c]['rod_position_peak'] / ref[c]['rod_position_final_8.0s'] - 1):.2f}"
             for c in ref] + [f"{100 * runs[r]['overshoot']:.2f}" for r in runs]
    print("| overshoot over the final value [%] | " + " | ".join(cells) + " |")
    # the spread of a noise realisation and the deviation from the reference, per point [µm]
    noisy = [r for r in runs if r.startswith("seed") or r.startswith("scene")]
    print("\n| figure | noise spread: max over seeds of abs(seed - no noise) [µm] | "
          "abs(MSL 4.1.0 - MSL 4.0.0) [µm] | h/5 - h [µm] | abs(scene - MSL 4.1.0) [µm] | "
          "abs(no noise - MSL 4.1.0) [µm] |")
    print("|---|---|---|---|---|---|")
    c41, c40 = list(ref)[0], list(ref)[1]
    for k in keys:
        spread = max(abs(runs[r][k] - runs["no noise"][k]) for r in noisy)
        print(f"| {k} | {1e6 * spread:.2f} | {1e6 * abs(ref[c41][ref_keys[k]] - ref[c40][ref_keys[k]]):.2f} | "
              f"{1e6 * (runs['no noise, h/5'][k] - runs['no noise'][k]):.3f} | "
              f"{1e6 * abs(runs['scene (seed 1)'][k] - ref[c41][ref_keys[k]]):.2f} | "
              f"{1e6 * abs(runs['no noise'][k] - ref[c41][ref_keys[k]]):.2f} |")
    # the figure docs/ema.md and the README quote: the scene's largest distance to MSL 4.1.0
    worst = max(keys, key=lambda k: abs(runs["scene (seed 1)"][k] - ref[c41][ref_keys[k]]))
    print(f"\nlargest abs(scene - MSL 4.1.0) over the compared rod positions: "
          f"{1e6 * abs(runs['scene (seed 1)'][worst] - ref[c41][ref_keys[worst]]):.2f} µm "
          f"({worst})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
