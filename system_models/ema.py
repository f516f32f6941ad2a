"""The electromechanical actuator (EMA): a scene turned into blocks, connections and a run.

Blocks, in Gauss–Seidel order: controller, motor, prsm, load.  Connections (:data:`CONNECTIONS`)::

    controller  v_d, v_q                 -> motor       v_d, v_q
    motor       torque                   -> prsm        screw_torque
    load        force                    -> prsm        load_force
    prsm        rod_position             -> controller  position,  load position
    prsm        rod_velocity             -> load        velocity
    prsm        screw_speed              -> controller  speed,     motor speed
    motor       i_d, i_q                 -> controller  i_d, i_q

Rigid couplings are lumped instead of co-simulated (docs/ema.md, "Coupling"): the motor's
rotor inertia is added to screw 1 (``stage[1].screw_inertia``) and the load mass to the last
nut (``stage[n].nut_mass``) inside the PRSM, which integrates their common motion.  What
crosses block boundaries is then the motor's electromagnetic torque (a function of the motor's
current state), the screw speed for the back-EMF, and the spring/damper/external force of the
load as a function of the rod's position and velocity.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any, Callable, Sequence


from prsm_fmu.models import make_model

from .controller import ControllerParams, CascadeController
from .load import LoadParams, SpringDamperLoad
from .master import Master, Result, RetryPolicy
from .motor import Motor, MotorParams
from .prsm import PRSMConfig, make_prsm_block
from .scenes import FIDELITIES, Scene
from .signals import make_profile

__all__ = ["System", "build_system", "CONNECTIONS", "steady_torque"]

#: target input -> source output
CONNECTIONS = {
    "controller.position": "prsm.rod_position",
    "controller.speed": "prsm.screw_speed",
    "controller.i_d": "motor.i_d",
    "controller.i_q": "motor.i_q",
    "motor.v_d": "controller.v_d",
    "motor.v_q": "controller.v_q",
    "motor.speed": "prsm.screw_speed",
    "prsm.screw_torque": "motor.torque",
    "prsm.load_force": "load.force",
    "load.position": "prsm.rod_position",
    "load.velocity": "prsm.rod_velocity",
}

_DESIGN_KEYS = {"sample_time", "current_bandwidth", "speed_ratio", "position_ratio",
                "speed_divider", "position_divider"}


@dataclass
class System:
    """A built actuator: the master and what went into it (for reports and checks)."""

    scene: Scene
    master: Master
    motor: MotorParams
    controller: ControllerParams
    load: LoadParams
    prsm: PRSMConfig
    prsm_kind: str
    inertia: float                    #: total inertia on the screw axis [kg·m²]
    lead_per_radian: float            #: c = Σ L/2π [m/rad]
    reference: Callable[[float], float]
    external_force: Callable[[float], float]
    initial: dict[str, float] = field(default_factory=dict)

    def run(self, progress=None) -> Result:
        """Run the scene to its end; the FMU instance is released afterwards, also on error."""
        try:
            return self.master.run(self.scene.t0 + self.scene.t_end, progress)
        finally:
            self.master.terminate()


def _overrides(cls, base, data: dict, where: str, skip=()):
    """``base`` with the fields named in ``data`` replaced; ValueError naming a bad field."""
    names = {f.name for f in fields(cls)}
    changes = {k: v for k, v in data.items() if k not in skip}
    unknown = set(changes) - names
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)} (allowed: {sorted(names)})")
    coerced = {}
    for k, v in changes.items():
        cur = getattr(base, k)
        if isinstance(cur, bool):
            ok = isinstance(v, bool)
        elif isinstance(cur, int):
            ok = isinstance(v, int) and not isinstance(v, bool)
        else:
            ok = isinstance(v, (int, float)) and not isinstance(v, bool)
        if not ok:
            raise ValueError(f"{where}: {k} = {v!r} must be {type(cur).__name__}")
        coerced[k] = type(cur)(v)
    return replace(base, **coerced)


def total_inertia(config: PRSMConfig) -> float:
    """Inertia on the screw axis [kg·m²]: 2 T at ω = 1 rad/s, carriers at equilibrium."""
    model = make_model(config.params(), "quasi-static", "torque")
    x = model.initial_state((0.0, 0.0), screw_speed=1.0)
    return 2.0 * model.kinetic_energy(x, (0.0, 0.0))


def steady_torque(config: PRSMConfig, fidelity: str, speed: float, load_force: float) -> float:
    """Motor torque [N.m] that holds ``speed`` against ``load_force`` (zero screw acceleration).

    Found on the model of the run's fidelity (``auto`` = quasi-static) with the carriers at
    their equilibrium; at zero speed the ideal torque c·F (inside the friction band any torque
    between the back-drive and drive limits holds the screw).
    """
    p = config.params()
    c = p.total_lead / (2.0 * math.pi)
    if speed == 0.0:
        return c * load_force
    level = "quasi-static" if fidelity == "auto" else fidelity
    opts = {"efficiency": float(config.solver()["kinematic_efficiency"])} if level == "kinematic" else {}
    model = make_model(p, level, "torque", **opts)

    def acc(torque: float) -> float:
        u = (torque, load_force)
        x = model.initial_state(u, screw_speed=speed, carrier_ratio=None)
        return model.outputs(0.0, x, u)["screw_acceleration"]

    t_ideal = c * load_force
    span = 2.0 * abs(t_ideal) + 1.0
    from .brent import brentq   # scipy's brentq, without importing scipy.optimize (~0.6 s)

    return brentq(acc, t_ideal - span, t_ideal + span, xtol=1e-14, rtol=1e-14)


def _nominals(motor: MotorParams, c: float, reference, scene: Scene, mode: str) -> dict[str, float]:
    """Typical magnitudes of the coupled outputs (scale of the coupling error estimate)."""
    peak = motor.torque_constant * motor.current_limit
    w = motor.no_load_speed
    stroke = c * w * scene.t_end
    if mode == "position":
        stroke = max(abs(reference(scene.t0 + scene.t_end * j / 64)) for j in range(65))
    stroke = max(stroke, 1e-3)
    return {"motor.i_d": motor.current_limit, "motor.i_q": motor.current_limit,
            "motor.torque": peak, "prsm.screw_speed": w, "prsm.rod_velocity": c * w,
            "prsm.rod_position": stroke, "load.force": peak / c}


def build_system(scene: Scene, prsm: str = "fmu", fmu_path=None, fidelity: str | None = None,
                 step: float | None = None, order: str | None = None,
                 extrapolation: int | None = None, retry: RetryPolicy | None = None,
                 record: Sequence[str] | None = None, loop: str = "python") -> System:
    """Blocks, connections and master for ``scene`` (options override the scene's values).

    Parameters
    ----------
    scene : Scene
    prsm : {"fmu", "python"}
        The PRSM as the FMU (fmpy) or as the plain Python model.
    fmu_path : path-like, optional
        The FMU (default ``dist/<mechanism>.fmu``; build it with :func:`system_models.fmu.ensure_fmu`).
    fidelity, step, order, extrapolation, retry
        Override the scene.
    record : sequence of str, optional
        ``"block.port"`` outputs to record (default: every output).  The blocks read only the
        outputs that are recorded or connected: the PRSM FMU's other variables are not read.
    loop : {"python", "native"}
        Who takes the macro steps: the Python master, or its translation to C
        (:class:`system_models.native_loop.NativeMaster`: the same outputs bit for bit, needs
        ``prsm = "fmu"``, gcc and a retry policy without a coupling tolerance).
    """
    from .native_loop import LOOPS, NativeMaster

    if loop not in LOOPS:
        raise ValueError(f"loop = {loop!r} is not allowed: must be one of {', '.join(LOOPS)}")
    t0 = scene.t0
    motor = _overrides(MotorParams, MotorParams(), scene.motor, f"scene {scene.name}: [motor]").validate()
    load = _overrides(LoadParams, LoadParams(), scene.load, f"scene {scene.name}: [load]",
                      skip=("external_force",)).validate()
    external = make_profile(scene.load.get("external_force", 0.0), "load.external_force")
    ini = dict(scene.initial)
    unknown = set(ini) - {"screw_speed", "rod_position", "carriers", "steady"}
    if unknown:
        raise ValueError(f"scene {scene.name}: [initial] unknown field(s) {sorted(unknown)}")
    w0 = float(ini.get("screw_speed", 0.0))
    x0 = float(ini.get("rod_position", 0.0))
    carriers = ini.get("carriers", "equilibrium")
    if carriers not in ("rest", "equilibrium"):
        raise ValueError(f"scene {scene.name}: initial.carriers = {carriers!r} is not allowed: "
                         "must be 'rest' or 'equilibrium'")
    fid = fidelity or scene.fidelity
    if fid not in FIDELITIES:
        raise ValueError(f"fidelity = {fid!r} is not allowed: must be one of {', '.join(FIDELITIES)}")
    # the PRSM with the rotor and the load mass lumped in (rigid couplings)
    pr = dict(scene.prsm)
    mechanism = pr.pop("mechanism", "PRSM2")
    extra = dict(pr.pop("parameters", {}))
    if pr:
        raise ValueError(f"scene {scene.name}: [prsm] unknown field(s) {sorted(pr)} "
                         "(allowed: mechanism, parameters)")
    base = PRSMConfig(mechanism, dict(extra)).params()
    n = base.n_stages
    c = base.total_lead / (2.0 * math.pi)
    params = dict(extra)
    params["stage[1].screw_inertia"] = base.stages[0].screw_inertia + motor.rotor_inertia
    params[f"stage[{n}].nut_mass"] = base.stages[-1].nut_mass + load.mass
    params.update(fidelity=fid, initial_screw_speed=w0, initial_screw_angle=x0 / c,
                  initial_carrier_equilibrium=carriers == "equilibrium")
    config = PRSMConfig(mechanism, params)
    inertia = total_inertia(config)
    # steady start: motor current, voltages and integrators that hold the initial motion
    f0 = load.force(t0, x0, c * w0, external)
    torque0 = steady_torque(config, fid, w0, f0) if ini.get("steady", False) else 0.0
    iq0 = torque0 / motor.torque_constant
    vd0, vq0 = motor.steady_voltages(w0, iq0)
    config.initial_inputs = (torque0, f0)
    # controller
    cs = dict(scene.controller)
    mode = cs.pop("mode", "position")
    if "reference" not in cs:
        raise ValueError(f"scene {scene.name}: controller.reference is missing")
    reference = make_profile(cs.pop("reference"), "controller.reference")
    design = {k: cs.pop(k) for k in list(cs) if k in _DESIGN_KEYS}
    cp = ControllerParams.design(motor, inertia, c, **design)
    cp = _overrides(ControllerParams, cp, cs, f"scene {scene.name}: [controller]").validate()
    initial_ctrl = {}
    if ini.get("steady", False):
        initial_ctrl = {"speed": iq0, "i_q": motor.resistance * iq0 if cp.decoupling else vq0,
                        "i_d": 0.0 if cp.decoupling else vd0, "v_d": vd0, "v_q": vq0,
                        "speed_ref": w0, "i_q_ref": iq0}
    blocks = [
        CascadeController(cp, motor, c, reference, mode=mode, t0=t0, initial=initial_ctrl),
        Motor(motor, i_q=iq0),
        make_prsm_block(config, prsm, fmu_path, start_time=t0),
        SpringDamperLoad(load, external, t0=t0),
    ]
    rp = retry if retry is not None else RetryPolicy(**scene.retry)
    try:
        master = (NativeMaster if loop == "native" else Master)(
                        blocks, CONNECTIONS, step if step is not None else scene.step, t0=t0,
                        order=order or scene.order,
                        extrapolation=scene.extrapolation if extrapolation is None else extrapolation,
                        retry=rp, nominals=_nominals(motor, c, reference, scene, mode),
                        record=record)
    except Exception:
        for b in blocks:
            b.terminate()
        raise
    return System(scene=scene, master=master, motor=motor, controller=cp, load=load,
                  prsm=config, prsm_kind=prsm, inertia=inertia, lead_per_radian=c,
                  reference=reference, external_force=external,
                  initial={"screw_speed": w0, "rod_position": x0, "torque": torque0,
                           "load_force": f0, "i_q": iq0})


def describe(system: System) -> dict[str, Any]:
    """Plain numbers of a built system (printed by the CLI, written to the summary)."""
    m, cp, ld = system.motor, system.controller, system.load
    c = system.lead_per_radian
    return {
        "inertia_on_screw_kg_m2": system.inertia,
        "reflected_mass_kg": system.inertia / c ** 2,
        "lead_per_radian_m": c,
        "motor_peak_torque_Nm": m.torque_constant * m.current_limit,
        "voltage_limit_V": m.voltage_limit,
        "no_load_speed_rad_s": m.no_load_speed,
        "controller_sample_time_s": cp.sample_time,
        "current_kp": cp.current_kp, "current_ki": cp.current_ki,
        "speed_kp": cp.speed_kp, "speed_ki": cp.speed_ki, "position_kp": cp.position_kp,
        "load_mass_kg": ld.mass, "load_stiffness_N_m": ld.stiffness,
        "load_damping_N_s_m": ld.damping,
    }
