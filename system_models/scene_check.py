"""A scene checked whole before anything runs: every mistake one line naming the field.

:func:`check_scene` builds the scene's blocks without the FMU (the plain Python PRSM stands in;
nothing is stepped), which validates every table and field the way a run would, and then checks
what a run would only find out late:

* every number finite (``nan`` never; ``inf`` only where a field means "none":
  :data:`INFINITE_OK`);
* ``outputs`` and every check's ``signal``/``signals`` name recorded outputs (the message lists
  the valid names);
* the run fits the stated bounds: at most :data:`MAX_STEPS` communication steps and at most
  :data:`MAX_RESULT_BYTES` of recorded outputs, and t_end − t0 is a whole number of steps;
* a geared scene's noise samples fall on the communication grid;
* the output directory can be written (:func:`check_output_dir`);
* the FMU has the scene's stage count (:func:`check_fmu_stages`).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

from .scenes import Scene

__all__ = ["check_scene", "check_output_dir", "check_fmu_stages", "MAX_STEPS", "MAX_RESULT_BYTES",
           "INFINITE_OK"]

#: most communication steps a run may take (≈ 0.1–0.3 ms each: 17 min at most)
MAX_STEPS = 5_000_000
#: most bytes the recorded outputs may take (float64, every output at every step)
MAX_RESULT_BYTES = 1 << 30
#: fields where ±inf means "none" (rigid gear, unlimited current, no end stop)
INFINITE_OK = {"gear.stiffness", "motor.current_limit", "load.stop_min", "load.stop_max"}


def _numbers(value: Any, where: str):
    """(dotted name, number) of every number in a parsed TOML value."""
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        yield where, value
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _numbers(v, f"{where}.{k}" if where else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _numbers(v, f"{where}[{i}]")


def _finite(scene: Scene) -> None:
    tables = {"t_end": scene.t_end, "step": scene.step, "t0": scene.t0,
              "extrapolation": scene.extrapolation, "controller": scene.controller,
              "motor": scene.motor, "load": scene.load, "prsm": scene.prsm,
              "initial": scene.initial, "retry": scene.retry, "gear": scene.gear}
    for i, c in enumerate(scene.checks, start=1):
        tables[f"check {i}"] = c
    for name, value in tables.items():
        for where, v in _numbers(value, name):
            if isinstance(v, float) and math.isnan(v):
                raise ValueError(f"scene {scene.name}: {where} = nan: every number must be finite")
            if isinstance(v, float) and math.isinf(v) and where not in INFINITE_OK:
                raise ValueError(f"scene {scene.name}: {where} = {v}: must be finite "
                                 f"(inf is allowed only for {', '.join(sorted(INFINITE_OK))})")


def _signals(check: dict) -> list[str]:
    out = [check["signal"]] if "signal" in check else []
    return out + list(check.get("signals", []))


def check_scene(scene: Scene, prsm: str = "fmu", fidelity: str | None = None,
                step: float | None = None, order: str | None = None,
                extrapolation: int | None = None, loop: str = "python") -> dict[str, Any]:
    """Check ``scene`` (with the run's overrides) whole; ValueError naming the field.

    Returns a few facts of the run it would be: ``steps``, ``outputs`` (count),
    ``result_bytes``, ``n_stages``.
    """
    from .master import ORDERS
    from .run import build_scene_system

    where = f"scene {scene.name}"
    _finite(scene)
    if loop == "native":
        from .native_loop import check_native_loop

        check_native_loop(scene.topology, prsm, scene.retry.get("tolerance"))
    if prsm == "native":
        from fmu_build.native import NATIVE_LEVELS

        level = fidelity or scene.fidelity
        if level not in NATIVE_LEVELS:
            raise ValueError(f"--prsm native: fidelity {level!r} is not allowed: must be one of "
                             f"{', '.join(NATIVE_LEVELS)}, the levels the native FMU runs (use "
                             f"--prsm fmu for {level}, or --fidelity with one of those)")
    if scene.order not in ORDERS:
        raise ValueError(f"{where}: order = {scene.order!r} is not allowed: must be one of "
                         f"{', '.join(ORDERS)}")
    if scene.extrapolation not in (0, 1):
        raise ValueError(f"{where}: extrapolation = {scene.extrapolation!r} is not allowed: "
                         "must be 0 or 1")
    if not math.isfinite(scene.t0):
        raise ValueError(f"{where}: t0 = {scene.t0!r} must be finite")
    h = scene.step if step is None else step
    if not (isinstance(h, (int, float)) and math.isfinite(h) and h > 0):
        raise ValueError(f"--step {h!r}: must be a finite number > 0 [s]")
    n = scene.t_end / h
    if n > MAX_STEPS:
        raise ValueError(f"{where}: t_end / step = {scene.t_end:g} s / {h:g} s = {n:.3g} steps "
                         f"exceeds the bound of {MAX_STEPS:.0e} steps (≈ 0.1–0.3 ms each): "
                         "shorten t_end or lengthen step")
    k = round(n)
    if k < 1 or abs(k * h - scene.t_end) > 1e-9 * max(scene.t_end, h):
        raise ValueError(f"--step {h!r} s: must divide the run of {where} into whole steps "
                         f"(t_end = {scene.t_end!r} s, t_end/step = {n!r})")
    system = build_scene_system(scene, prsm="python", fidelity=fidelity, step=h, order=order,
                                extrapolation=extrapolation)
    try:
        names = [f"{b.name}.{p.name}" for b in system.master.blocks for p in b.outputs]
    finally:
        system.master.terminate()
    valid = set(names)
    for o in scene.outputs:
        if o not in valid:
            raise ValueError(f"{where}: outputs: {o!r} is not an output of this scene's blocks "
                             f"(valid: {', '.join(names)})")
    for i, c in enumerate(scene.checks, start=1):
        for s in _signals(c):
            if s not in valid:
                raise ValueError(f"{where}: check {i} ({c['kind']}): signal {s!r} is not an output "
                                 f"of this scene's blocks (valid: {', '.join(names)})")
        if c["kind"] == "energy_balance" and scene.topology != "direct":
            raise ValueError(f"{where}: check {i}: energy_balance needs the PMSM's electrical "
                             "energies (topology = \"direct\")")
    size = 8 * (k + 1) * (len(names) + 1)
    if size > MAX_RESULT_BYTES:
        raise ValueError(f"{where}: the recorded outputs would take {size / 2**30:.3g} GiB "
                         f"({k + 1} points × {len(names)} outputs), above the bound of "
                         f"{MAX_RESULT_BYTES / 2**30:.3g} GiB: shorten t_end or lengthen step")
    if scene.topology == "geared":
        noise = (scene.controller.get("sensor") or {}).get("noise")
        if noise and "sample_period" in noise:
            r = noise["sample_period"] / h
            if abs(r - round(r)) > 1e-9 * r or round(r) < 1:
                raise ValueError(f"{where}: controller.sensor.noise.sample_period = "
                                 f"{noise['sample_period']!r} s must be a whole number of steps "
                                 f"of {h!r} s (its samples must fall on the grid)")
    return {"steps": k, "outputs": len(names), "result_bytes": size,
            "n_stages": system.prsm.n_stages}


def check_output_dir(path: str | os.PathLike) -> None:
    """ValueError naming ``--out`` if the directory cannot be created or written.

    Creates the directory (the run will write there) and a probe file, which it removes: the
    permission bits alone do not tell (root passes every check; /proc refuses anyway).
    """
    import tempfile

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"--out {str(p)!r} exists and is not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p, prefix=".prsm-ema-probe-"):
            pass
    except OSError as exc:
        raise ValueError(f"--out {str(p)!r}: cannot write there ({exc.strerror or exc})") from None


def check_fmu_stages(fmu_path: str | os.PathLike, n_stages: int, mechanism: str,
                     native: bool = False) -> None:
    """ValueError naming ``--fmu`` if the FMU's stage count is not the scene's, or (``native``:
    the run asked for ``--prsm native``) if it is not a native FMU (modelIdentifier
    ``<name>_native``, docs/fmu.md *The native FMU*)."""
    from fmpy import read_model_description

    try:
        md = read_model_description(str(fmu_path))
    except Exception as exc:  # noqa: BLE001 - any unreadable file is the same mistake
        raise ValueError(f"--fmu {str(fmu_path)!r} cannot be read as an FMU: {exc}") from None
    ident = md.coSimulation.modelIdentifier if md.coSimulation else ""
    if native and not ident.endswith("_native"):
        raise ValueError(f"--fmu {str(fmu_path)!r} is not a native FMU (modelIdentifier "
                         f"{ident!r}) but --prsm native asks for one: give --fmu "
                         f"dist/{mechanism}-native.fmu, or --prsm fmu to run this one")
    names = {v.name for v in md.modelVariables}
    k = 0
    while f"stage[{k + 1}].contact_force" in names:
        k += 1
    if k != n_stages:
        raise ValueError(f"--fmu {str(fmu_path)!r} is a {k}-stage PRSM; the scene's mechanism "
                         f"{mechanism} has {n_stages} stage(s): give --fmu dist/{mechanism}.fmu")
