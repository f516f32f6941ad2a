"""Run a scene end to end: build the actuator, co-simulate, evaluate the scene's checks."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .analysis import CheckResult, energy_balance, evaluate
from .ema import System, build_system, describe
from .master import Result, RetryPolicy
from .scenes import Scene, load_scene

__all__ = ["SceneRun", "run_scene", "build_scene_system", "describe_system"]


def build_scene_system(scene: Scene, **options) -> System:
    """The scene's blocks and master for its topology (``direct``: :func:`.ema.build_system`,
    ``geared``: :func:`.geared.build_geared_system`); options as :func:`run_scene`'s."""
    loop = options.pop("loop", "python")
    if loop != "python":
        from .native_loop import check_native_loop

        check_native_loop(scene.topology, options.get("prsm", "fmu"))
    if scene.topology == "geared":
        from .geared import build_geared_system

        return build_geared_system(scene, **options)
    return build_system(scene, loop=loop, **options)


def describe_system(system: System) -> dict[str, Any]:
    """Plain numbers of a built system, for its topology."""
    if system.scene.topology == "geared":
        from .geared import describe_geared

        return describe_geared(system)
    return describe(system)


@dataclass
class SceneRun:
    """A finished run: the system, its outputs, the checks and the energy bookkeeping."""

    scene: Scene
    system: System
    result: Result
    checks: list[CheckResult]
    energy: dict[str, float] = field(default_factory=dict)

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def summary(self) -> dict[str, Any]:
        r = self.result
        return {
            "scene": self.scene.name, "description": self.scene.description,
            "prsm": self.system.prsm_kind,
            "fidelity": self.system.prsm.solver()["fidelity"],
            "step": self.system.master.step, "order": self.system.master.order,
            "extrapolation": self.system.master.extrapolation, "t_end": float(r.time[-1]),
            "system": describe_system(self.system),
            "stats": {k: v for k, v in r.stats.items()},
            "final": {n: float(r[n][-1]) for n in self.scene.outputs if n in r},
            "energy": self.energy,
            "checks": [{"kind": c.kind, "signal": c.signal, "passed": c.passed,
                        "measured": c.measured, "limits": c.limits, "text": c.text}
                       for c in self.checks],
            "passed": self.passed,
        }


def run_scene(scene: Scene | str, prsm: str = "fmu", fmu_path=None, fidelity: str | None = None,
              step: float | None = None, order: str | None = None,
              extrapolation: int | None = None, retry: RetryPolicy | None = None,
              progress=None, loop: str = "python") -> SceneRun:
    """Build and run ``scene`` (a :class:`Scene` or a name/path); evaluate its checks.

    With ``prsm="fmu"`` the FMU at ``fmu_path`` (default ``dist/<mechanism>.fmu``) must exist:
    :func:`system_models.fmu.ensure_fmu` builds it.  ``loop = "native"``: the macro steps
    taken in C (:class:`system_models.native_loop.NativeMaster`, the same outputs bit for bit).

    Raises
    ------
    system_models.master.CoSimulationError
        If a step is refused and no retry can take it (time, block and reason in the message).
    """
    sc = load_scene(scene) if isinstance(scene, str) else scene
    system = build_scene_system(sc, prsm=prsm, fmu_path=fmu_path, fidelity=fidelity, step=step,
                                order=order, extrapolation=extrapolation, retry=retry,
                                loop=loop)
    res = system.run(progress)
    checks = evaluate(res, sc.checks, {"reference": system.reference,
                                       "params": system.prsm.params()})
    # the power bookkeeping needs the PMSM's electrical energies (direct topology)
    energy = energy_balance(res) if sc.topology == "direct" else {}
    return SceneRun(sc, system, res, checks, energy)
