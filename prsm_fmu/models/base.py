"""The interface every fidelity level shares: pure functions of time, state and inputs.

Drive modes
-----------
``torque``  (the FMU's): inputs u = (screw_torque [N·m], load_force [N]); the screw's motion
            follows from the balances.
``speed``   (the papers'): the screw's motion is prescribed.  Inputs u = (screw_acceleration
            [rad/s²], load_force [N]), held over a step; the screw speed is a state that
            integrates the prescribed acceleration, so a speed profile ω(t) is followed
            exactly where it is piecewise linear (:func:`prsm_fmu.simulate` turns a profile
            into accelerations, :mod:`prsm_fmu.profiles`).  The driven torques are outputs and
            carry every inertia term J·α.

State layout (both drives): ``screw_angle`` [rad], ``screw_speed`` [rad/s], the carrier speeds
``carrier_k_speed`` [rad/s] (dynamic level only), then the energy accumulators
``input_work``, ``output_work``, ``friction_work`` [J] (integrals of motor power, load power and
friction power).  Sign conventions: docs/architecture.md §4.
"""

from __future__ import annotations

import math
import sys
from abc import ABC
from typing import Any
from weakref import WeakKeyDictionary

from ..mechanics import Mechanism
from ..param_ranges import speed_bounds
from ..params import MAX_SCREW_SPEED, MechanismParams

DRIVES = ("torque", "speed")

#: friction terms with a power output ``friction_power_<term>`` each [W]; they sum to
#: ``friction_power``: screw–roller Coulomb (spin sliding), viscous (lubricant) and
#: differential sliding, and the Coulomb friction of the joints (splines, thrust bearings)
FRICTION_TERMS = ("coulomb", "viscous", "differential", "joints")


class Model(ABC):
    """One fidelity level of the mechanism (see module docstring for inputs and states).

    Parameters
    ----------
    params : MechanismParams
        The mechanism; validated on construction.
    drive : {"torque", "speed"}
        Drive mode.
    """

    fidelity: str = ""
    carriers: str = "dynamic"

    def __init__(self, params: MechanismParams, drive: str = "torque") -> None:
        if drive not in DRIVES:
            raise ValueError(f"drive = {drive!r} is not allowed: must be one of {DRIVES}")
        self.params = params
        self.drive = drive
        self.mechanism = Mechanism(params, self.carriers)
        n = params.n_stages
        self.n_carrier_states = n if self.carriers == "dynamic" else 0
        names = ["screw_angle", "screw_speed"]
        names += [f"carrier_{k}_speed" for k in range(1, self.n_carrier_states + 1)]
        names += ["input_work", "output_work", "friction_work"]
        self.state_names: tuple[str, ...] = tuple(names)
        self.n_states = len(names)
        self._i_carrier = 2
        self._torque_drive = drive == "torque"
        #: no losses outside the mechanism model (the hot path skips the hook)
        self._lossless = type(self)._extra_loss_torque is Model._extra_loss_torque
        self._i_energy = self._i_carrier + self.n_carrier_states
        #: per-state absolute scale for error norms [rad, rad/s, rad/s, J]
        self.state_scale = tuple(1.0 for _ in names)
        self.error_mask = tuple(True for _ in names)
        #: states that no derivative depends on (screw angle, work integrals): steppers may skip
        #: their Jacobian columns
        self.quadrature_states = (0, self._i_energy, self._i_energy + 1, self._i_energy + 2)
        stage_outputs = []
        for k in range(1, n + 1):
            stage_outputs += [f"stage[{k}].contact_force", f"stage[{k}].normal_force",
                              f"stage[{k}].driven_torque", f"stage[{k}].spline_friction",
                              f"stage[{k}].carrier_speed", f"stage[{k}].carrier_speed_ratio"]
        self.output_names: tuple[str, ...] = tuple(
            ["screw_speed", "screw_angle", "screw_acceleration", "screw_torque", "rod_position",
             "rod_velocity", "load_force"] + stage_outputs
            + ["efficiency", "friction_power", "input_power", "output_power", "input_work",
               "output_work", "friction_work", "kinetic_energy"]
            + [f"friction_power_{term}" for term in FRICTION_TERMS]
            + ["screw_friction_torque", "overall_efficiency"])
        #: inertia reflected to screw 1 of everything slaved to it [kg·m²] (screw_friction_torque)
        self._j_eq = self.mechanism.equivalent_inertia()
        #: the per-stage output names, made once (the outputs are read at every step)
        self._stage_keys = tuple(tuple(f"stage[{k}].{q}" for q in (
            "contact_force", "normal_force", "driven_torque", "spline_friction", "carrier_speed",
            "carrier_speed_ratio")) for k in range(1, n + 1))
        self._term_keys = tuple((term, f"friction_power_{term}") for term in FRICTION_TERMS)

    # ---- hooks for levels with extra losses (kinematic efficiency) ------------------------
    def _extra_loss_torque(self, omega: float, load: float) -> float:
        """Torque on screw 1 opposing rotation from losses outside the mechanism model [N·m]."""
        return 0.0

    def _extra_loss_terms(self, omega: float, load: float) -> dict[str, float]:
        """:meth:`_extra_loss_torque`'s power split over :data:`FRICTION_TERMS` [W]."""
        return {"coulomb": self._extra_loss_torque(omega, load) * omega}

    # ---- interface -------------------------------------------------------------------------
    def initial_state(self, u: tuple, screw_speed: float = 0.0, screw_angle: float = 0.0,
                      carrier_ratio: float | None = 0.0) -> list[float]:
        """State at the start of a run.

        Parameters
        ----------
        u : tuple
            Inputs at the start (unused; kept for the interface).
        screw_speed : float
            Initial screw speed [rad/s] (speed drive: the prescribed speed at the start).
        screw_angle : float
            Initial screw angle [rad].
        carrier_ratio : float or None
            Initial carrier speed / screw speed [-] for the dynamic level; ``None`` puts the
            carriers at their equilibrium ratio.  Default 0: carriers at rest (Li et al.'s (2021) start).

        Returns
        -------
        list of float
        """
        omega = float(screw_speed)
        x = [float(screw_angle), omega]
        for s in self.mechanism.stages[: self.n_carrier_states]:
            ratio = s.zeta_geometric if carrier_ratio is None else float(carrier_ratio)
            x.append(ratio * omega)
        return x + [0.0, 0.0, 0.0]

    def _unpack(self, x, u):
        return x[1], x[2:2 + self.n_carrier_states], u[1]

    def _solve(self, x, u, detail: bool):
        omega, wp, load = self._unpack(x, u)
        loss = self._extra_loss_torque(omega, load)
        if self.drive == "torque":
            sol = self.mechanism.solve(omega, wp, load, torque=u[0] - loss, detail=detail)
            motor = u[0]
        else:
            sol = self.mechanism.solve(omega, wp, load, acceleration=u[0], detail=detail)
            motor = sol.motor_torque + loss
        return omega, wp, load, motor, loss, sol

    def rhs(self, t: float, x: list[float], u: tuple) -> list[float]:
        """Time derivative of the state (the hot path).

        Parameters
        ----------
        t : float
            Time [s] (the model is autonomous; kept for the stepper interface).
        x : list of float
            State (layout: module docstring).
        u : tuple
            Inputs held over the step.

        Returns
        -------
        list of float
        """
        load = u[1]
        mech = self.mechanism
        omega = x[1]
        loss = 0.0 if self._lossless else self._extra_loss_torque(omega, load)
        if self._torque_drive:
            motor = u[0]
            alpha, _, acc, p_fric = mech.rates(omega, x[2:self._i_energy], load, motor - loss)
        else:
            alpha = u[0]
            _, motor, acc, p_fric = mech.rates(omega, x[2:self._i_energy], load,
                                               acceleration=alpha)
            motor += loss
        dx = [omega, alpha]
        if self.n_carrier_states:
            dx += acc
        dx += (motor * omega, load * mech.c_out * omega, p_fric + loss * omega)
        return dx

    def sliding_velocities(self, x: list[float]) -> list[tuple]:
        """Sliding velocity of every regularised friction law at state ``x`` [m/s], one tuple
        of components per law: the mechanism's contacts, splines and bearings
        (:meth:`prsm_fmu.mechanics.Mechanism.sliding_velocities`), then ω·ΣL/2π where a level's
        own Coulomb-like loss acts.  The adaptive steppers end an internal step on each kink
        speed (:attr:`kink_speeds`) that a step would cross (docs/accuracy.md, "Landing on the
        friction law's kinks")."""
        omega = x[1]
        out = self.mechanism.sliding_velocities(omega, x[2:self._i_energy])
        if getattr(self, "coulomb_loss", False):
            out.append((omega * self.mechanism.c_out,))
        return out

    @property
    def kink_speeds(self) -> tuple:
        """Per entry of :meth:`sliding_velocities`, the sliding speeds [m/s] where its law is
        only C¹ (:meth:`prsm_fmu.mechanics.Mechanism.kink_speeds`; the loss law's are a
        one-component law's, 0 and v_ε)."""
        kinks = self.__dict__.get("_kink_speeds")
        if kinks is None:
            kinks = self.mechanism.kink_speeds()
            if getattr(self, "coulomb_loss", False):
                kinks += ((0.0, self.mechanism.v_eps),)
            self._kink_speeds = kinks
        return kinks

    def outputs(self, t: float, x: list[float], u: tuple) -> dict[str, float]:
        """All outputs (the names of docs/fmu.md, "Variables"), consistent with :meth:`rhs`.

        Returns
        -------
        dict
            Output name → value in SI units.
        """
        omega, wp, load, motor, loss, sol = self._solve(x, u, True)
        mech = self.mechanism
        wps = mech.carrier_speeds(omega, wp)
        c_out = mech.c_out
        v_rod = c_out * omega
        p_in = motor * omega
        p_out = load * v_rod
        y = {
            "screw_speed": omega, "screw_angle": x[0],
            "screw_acceleration": sol.screw_acceleration,
            "screw_torque": motor, "rod_position": c_out * x[0], "rod_velocity": v_rod,
            "load_force": load,
        }
        for k, (contact, normal, driven, spline, carrier, ratio) in enumerate(self._stage_keys):
            y[contact] = sol.contact_force[k]
            y[normal] = sol.normal_force[k]
            y[driven] = motor if k == 0 else sol.driven_torque[k]
            y[spline] = sol.spline_friction[k]
            y[carrier] = wps[k]
            y[ratio] = wps[k] / omega if omega != 0.0 else 0.0
        y["efficiency"] = efficiency(p_in, p_out, omega)
        y["friction_power"] = sol.friction_power + loss * omega
        terms = sol.friction_power_terms
        if loss:
            terms = dict(terms)
            for term, p in self._extra_loss_terms(omega, load).items():
                terms[term] += p
        for term, key in self._term_keys:
            y[key] = terms[term]
        # the friction-torque article's M_f: the friction's generalized force on the screw angle, i.e. what the
        # motor torque spends beyond the load's torque and the slaved parts' inertial torque
        y["screw_friction_torque"] = motor - load * c_out - self._j_eq * sol.screw_acceleration
        y["input_power"] = p_in
        y["output_power"] = p_out
        ie = self._i_energy
        y["input_work"], y["output_work"], y["friction_work"] = x[ie], x[ie + 1], x[ie + 2]
        y["kinetic_energy"] = self.kinetic_energy(x, u)
        y["overall_efficiency"] = overall_efficiency(x[ie], x[ie + 1])
        return y

    def contact_diagnosis(self, x: list[float], u: tuple) -> str | None:
        """Why the rigid contact has no solution at this state, or None where it has one.

        Only the torque drive can meet such a state (a prescribed acceleration always has
        exactly one solution); see :meth:`prsm_fmu.mechanics.Mechanism.diagnose`.
        """
        if not self._torque_drive or not is_finite_state(x):
            return None
        omega, wp, load = self._unpack(x, u)
        loss = 0.0 if self._lossless else self._extra_loss_torque(omega, load)
        return self.mechanism.diagnose(omega, wp, load, u[0] - loss)

    def kinetic_energy(self, x: list[float], u: tuple) -> float:
        """Kinetic energy of all moving parts [J]."""
        omega, wp, _ = self._unpack(x, u)
        return self.mechanism.kinetic_energy(omega, wp)

    def fastest_time_constant(self, x: list[float], u: tuple) -> float:
        """Fastest time constant of the state at this point [s] (carriers; inf if none)."""
        omega, wp, load = self._unpack(x, u)
        return self.mechanism.fastest_time_constant(omega, wp, load)


#: |screw speed| [rad/s] at or below which no power flows (:func:`efficiency`):
#: 4 eps · MAX_SCREW_SPEED = 4 × 2.22e-16 × 1e4 rad/s = 8.9e-12 rad/s.  A speed is a sum of
#: rounded terms (ω + α h per step, the start value) each rounded to eps/2 of a speed up to
#: MAX_SCREW_SPEED, so a speed this small cannot be told from the rounding of the speeds a run
#: can have; the powers M·ω and F·c·ω are then rounding noise and their ratio is 0/0 (a loop
#: holding position reads ω = −2e-17 rad/s and would give η = 1.0)
STANDSTILL_SPEED = 4.0 * sys.float_info.epsilon * MAX_SCREW_SPEED


#: outputs that are NaN where they are not defined (:func:`efficiency` where no power flows);
#: every other output is finite, and the checks for finite outputs allow NaN in these only
MAY_BE_UNDEFINED = frozenset({"efficiency"})


def undefined_allowed(name: str, value: float) -> bool:
    """Whether ``value`` of output ``name`` (``prsm.efficiency`` or ``efficiency``) is the NaN
    of an undefined output (:data:`MAY_BE_UNDEFINED`) rather than a failure."""
    return math.isnan(value) and name.rpartition(".")[2] in MAY_BE_UNDEFINED


def efficiency(p_in: float, p_out: float, speed: float) -> float:
    """Instantaneous efficiency [-] from motor power and load power [W] at screw speed [rad/s].

    Forward drive (motor delivers power, load absorbs it or none): P_out / P_in, which is seed
    000 Eq. 28 η = F_N Σ L / (2π M_S1).  Back-driving (load delivers power, motor absorbs it or
    none): P_in / P_out.  NaN where no power passes through the mechanism from one side to the
    other, so that there is nothing to rate: at standstill (|speed| ≤ :data:`STANDSTILL_SPEED`,
    or both powers exactly 0), and where both sides deliver power (all of it is lost in
    friction or stored) or both absorb it (stored kinetic energy is released into both).
    """
    if not abs(speed) > STANDSTILL_SPEED:
        return math.nan
    if p_in > 0.0 and p_out >= 0.0:
        return p_out / p_in
    if p_out < 0.0 and p_in <= 0.0:
        return p_in / p_out + 0.0           # + 0.0: no −0.0 when the motor absorbs nothing
    return math.nan


def overall_efficiency(input_work: float, output_work: float) -> float:
    """Overall efficiency over an interval [-]: the friction-torque article's work ratio ∫P_out dt / ∫P_in dt.

    Parameters
    ----------
    input_work, output_work : float
        Work of the motor torque and work done on the load over the interval [J] (differences
        of the ``input_work`` and ``output_work`` outputs between its ends).

    Returns
    -------
    float
        W_out / W_in when the motor has put work in (W_in > 0), else 0 (no work in).
    """
    return output_work / input_work if input_work > 0.0 else 0.0


def is_finite_state(x) -> bool:
    """Whether every state component is finite."""
    return all(math.isfinite(v) for v in x)


_SPEED_BOUNDS: WeakKeyDictionary = WeakKeyDictionary()


def model_speed_bounds(model: Any, n: int) -> tuple[float, ...]:
    """:func:`prsm_fmu.param_ranges.speed_bounds` of ``model``'s state of length ``n`` (speeds x[1] .. x[n-4]): J_i is
    twice the kinetic energy (``Model.kinetic_energy`` of the model's own level, for ``auto``
    the dynamic level's) of the state with speed i at 1 rad/s and everything else 0; cached
    per model.  The native FMU computes the same J_i from its model's equivalent and carrier
    inertias with the same operations (prsm_fmi2.c)."""
    key = _SPEED_BOUNDS.get(model)
    if key is not None and key[0] == n:
        return key[1]
    inertias = []
    for i in range(1, n - 3):
        x = [0.0] * n
        x[i] = 1.0
        inertias.append(2.0 * Model.kinetic_energy(model, x, (0.0, 0.0)))
    bounds = speed_bounds(inertias)
    _SPEED_BOUNDS[model] = (n, bounds)
    return bounds
