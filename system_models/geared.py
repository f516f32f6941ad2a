"""The ``geared`` topology: a scene turned into a current-fed, geared actuator with a gap contact.

Blocks, in Gauss–Seidel order, and what flows between them::

    controller  current_command         -> motor       current_command
    motor       torque                  -> gear        motor_torque
    gear        motor_speed             -> motor       speed
    gear        motor_angle             -> controller  angle        (the sensor adds noise)
    gear        screw_torque            -> prsm        screw_torque
    prsm        screw_angle, _speed,
                _acceleration           -> gear
    load        force                   -> gear        load_force
    load        force                   -> prsm        load_force
    prsm        rod_position, _velocity -> load

* ``controller`` (:class:`~system_models.continuous_controller.ContinuousCascade`): position
  PI on the measured motor angle, speed from a derivative filter, speed PI, with a
  :class:`~system_models.noise.Sensor` (seeded noise, quantisation);
* ``motor`` (:class:`~system_models.current_motor.CurrentFedMotor`): ideal current source
  behind a first-order bus delay;
* ``gear`` (:class:`~system_models.gear.RigidGear`): ratio, mesh losses with a stuck mode,
  backlash and compliance resolved on the light output side; the rotor is lumped into the
  PRSM (``stage[1].screw_inertia`` += N² J_m);
* ``prsm``: the FMU (or the plain Python model);
* ``load`` (:class:`~system_models.contact.GapContactLoad`): the load mass behind an elastic
  gap contact, and the rod's end stops.

Scene tables: ``[controller]`` (ContinuousCascadeParams fields, ``reference`` profile,
``sensor = {noise = {kind, sample_period, seed, low, high | std}, resolution}``), ``[motor]``
(CurrentFedMotorParams), ``[gear]`` (GearParams, ``initial_side``), ``[load]``
(ContactParams, ``external_force`` profile), ``[prsm]`` (``mechanism``, ``parameters``),
``[initial]`` (nothing yet: the rod starts where the loaded gear puts it with the motor at 0).
"""

from __future__ import annotations

import math
from typing import Any

from .contact import ContactParams, GapContactLoad
from .continuous_controller import ContinuousCascade, ContinuousCascadeParams
from .current_motor import CurrentFedMotor, CurrentFedMotorParams
from .ema import System, _overrides, total_inertia
from .gear import GearParams, RigidGear
from .master import Master, RetryPolicy
from .noise import SampledNoise, Sensor
from .prsm import PRSMConfig, make_prsm_block
from .scenes import FIDELITIES, Scene
from .signals import make_profile

__all__ = ["CONNECTIONS", "build_geared_system", "describe_geared", "make_sensor"]

#: target input -> source output
CONNECTIONS = {
    "controller.angle": "gear.motor_angle",
    "motor.current_command": "controller.current_command",
    "motor.speed": "gear.motor_speed",
    "gear.motor_torque": "motor.torque",
    "gear.screw_angle": "prsm.screw_angle",
    "gear.screw_speed": "prsm.screw_speed",
    "gear.screw_acceleration": "prsm.screw_acceleration",
    "gear.load_force": "load.force",
    "prsm.screw_torque": "gear.screw_torque",
    "prsm.load_force": "load.force",
    "load.position": "prsm.rod_position",
    "load.velocity": "prsm.rod_velocity",
}

_NOISE_KEYS = {"kind", "sample_period", "seed", "low", "high", "std", "start"}


def make_sensor(spec: Any, where: str = "controller.sensor") -> Sensor:
    """A :class:`Sensor` from ``{noise = {...}, resolution = ...}`` (absent: a perfect one)."""
    if spec is None:
        return Sensor()
    if not isinstance(spec, dict):
        raise ValueError(f"{where} must be a table {{noise = {{...}}, resolution = ...}}")
    unknown = set(spec) - {"noise", "resolution"}
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)} (allowed: noise, resolution)")
    noise = None
    if "noise" in spec:
        n = spec["noise"]
        if not isinstance(n, dict):
            raise ValueError(f"{where}.noise must be a table")
        bad = set(n) - _NOISE_KEYS
        if bad:
            raise ValueError(f"{where}.noise: unknown field(s) {sorted(bad)} "
                             f"(allowed: {sorted(_NOISE_KEYS)})")
        try:
            noise = SampledNoise(**n)
        except TypeError as exc:
            raise ValueError(f"{where}.noise: {exc}") from None
    res = spec.get("resolution", 0.0)
    if isinstance(res, bool) or not isinstance(res, (int, float)):
        raise ValueError(f"{where}.resolution = {res!r} must be a number")
    return Sensor(noise, float(res))


def build_geared_system(scene: Scene, prsm: str = "fmu", fmu_path=None,
                        fidelity: str | None = None, step: float | None = None,
                        order: str | None = None, extrapolation: int | None = None,
                        retry: RetryPolicy | None = None) -> System:
    """Blocks, connections and master of a ``geared`` scene (options override the scene's)."""
    name = scene.name
    t0 = scene.t0
    motor = _overrides(CurrentFedMotorParams, CurrentFedMotorParams(), scene.motor,
                       f"scene {name}: [motor]").validate()
    gspec = dict(scene.gear)
    side = gspec.pop("initial_side", 0)
    gear = _overrides(GearParams, GearParams(), gspec, f"scene {name}: [gear]").validate()
    load = _overrides(ContactParams, ContactParams(), scene.load, f"scene {name}: [load]",
                      skip=("external_force",)).validate()
    external = make_profile(scene.load.get("external_force", 0.0), "load.external_force")
    if scene.initial:
        raise ValueError(f"scene {name}: [initial] unknown field(s) {sorted(scene.initial)} "
                         "(a geared scene starts at rest with the motor at angle 0)")
    fid = fidelity or scene.fidelity
    if fid not in FIDELITIES:
        raise ValueError(f"fidelity = {fid!r} is not allowed: must be one of {', '.join(FIDELITIES)}")
    cs = dict(scene.controller)
    cs.pop("kind", None)
    if "reference" not in cs:
        raise ValueError(f"scene {name}: controller.reference is missing")
    reference = make_profile(cs.pop("reference"), "controller.reference")
    sensor = make_sensor(cs.pop("sensor", None))
    cp = _overrides(ContinuousCascadeParams, ContinuousCascadeParams(), cs,
                    f"scene {name}: [controller]").validate()
    # the PRSM with the rotor lumped in (through the gear: N² J_m on the screw)
    pr = dict(scene.prsm)
    mechanism = pr.pop("mechanism", "PRSM1")
    extra = dict(pr.pop("parameters", {}))
    if pr:
        raise ValueError(f"scene {name}: [prsm] unknown field(s) {sorted(pr)} "
                         "(allowed: mechanism, parameters)")
    base = PRSMConfig(mechanism, dict(extra)).params()
    c = base.total_lead / (2.0 * math.pi)
    n = gear.ratio
    # start: at rest, the motor at angle 0, the gear on the flank the load presses it against
    # and deflected by the load's static torque (quasi-static output side)
    f0 = external(t0)
    beta0 = 0.5 * gear.backlash * side
    tout0 = -c * f0                      # torque the mesh must give the screw to hold F
    delta0 = -tout0 / gear.stiffness if math.isfinite(gear.stiffness) else 0.0
    theta0 = beta0 + delta0              # motor at 0: θ_s = φ_rel
    params = dict(extra)
    params["stage[1].screw_inertia"] = base.stages[0].screw_inertia + n * n * motor.rotor_inertia
    params.update(fidelity=fid, initial_screw_speed=0.0, initial_screw_angle=theta0,
                  initial_carrier_equilibrium=True)
    config = PRSMConfig(mechanism, params)
    inertia = total_inertia(config)
    x0 = c * theta0
    # contact force at the start: the load in equilibrium with its external force
    if load.bilateral:
        xl0 = x0 + load.gap - f0 / load.stiffness
    else:
        xl0 = x0 + load.gap - max(f0, 0.0) / load.stiffness
    config.initial_inputs = (0.0, f0 if (load.bilateral or f0 > 0) else 0.0)
    blocks = [
        ContinuousCascade(cp, reference, sensor, t0=t0, initial_angle=0.0),
        CurrentFedMotor(motor),
        RigidGear(gear, motor.rotor_inertia, inertia - n * n * motor.rotor_inertia, c,
                  initial_screw_angle=theta0, initial_side=side, initial_deflection=delta0),
        make_prsm_block(config, prsm, fmu_path, start_time=t0),
        GapContactLoad(load, external, t0=t0, load_position=xl0),
    ]
    rp = retry if retry is not None else RetryPolicy(**scene.retry)
    try:
        master = Master(blocks, CONNECTIONS, step if step is not None else scene.step, t0=t0,
                        order=order or scene.order,
                        extrapolation=scene.extrapolation if extrapolation is None else extrapolation,
                        retry=rp)
    except Exception:
        for b in blocks:
            b.terminate()
        raise
    system = System(scene=scene, master=master, motor=motor, controller=cp, load=load,
                    prsm=config, prsm_kind=prsm, inertia=inertia, lead_per_radian=c,
                    reference=reference, external_force=external,
                    initial={"screw_angle": theta0, "rod_position": x0, "load_position": xl0,
                             "load_force": f0})
    system.gear = gear          # type: ignore[attr-defined]
    return system


def describe_geared(system: System) -> dict[str, Any]:
    """Plain numbers of a built geared system (printed by the CLI, written to the summary)."""
    m, cp, ld = system.motor, system.controller, system.load
    g = system.gear             # type: ignore[attr-defined]
    c = system.lead_per_radian
    own = system.inertia - g.ratio ** 2 * m.rotor_inertia
    return {
        "inertia_on_screw_kg_m2": system.inertia,
        "reflected_mass_kg": system.inertia / c ** 2,
        "prsm_own_inertia_on_screw_kg_m2": own,
        "lead_per_radian_m": c,
        "gear_ratio": g.ratio, "rod_per_motor_radian_m": c / g.ratio,
        "motor_torque_constant_Nm_A": m.torque_constant,
        "motor_rotor_inertia_kg_m2": m.rotor_inertia, "bus_delay_s": m.bus_delay,
        "motor_peak_torque_Nm": m.torque_constant * m.current_limit,
        "controller_sample_time_s": 0.0,
        "position_gain": cp.position_gain, "speed_gain": cp.speed_gain,
        "load_mass_kg": ld.mass, "contact_stiffness_N_m": ld.stiffness,
        "contact_damping_N_s_m": ld.damping,
    }
