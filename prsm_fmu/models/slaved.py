"""Closed-form advance of the levels whose carriers are slaved to the screw (quasi-static, kinematic).

With the carriers at a fixed ratio, every slip direction is fixed by the sign of ω, and outside
the friction band (every sliding speed ≥ v_ε, friction.py) the Coulomb law transmits forces that
do not depend on the slip speed. The balances of mechanics.py are then linear and homogeneous in
(load F, screw acceleration α) for a given sign pattern (which flank carries each stage, signs
of the spline torques and bearing forces), so under held inputs

    α = (M_motor − K_F F) / K_α                 (constant over the step)
    P_friction / |ω| = Q_F F + Q_α α            (friction power proportional to speed)

and the state after a step h is exact: θ += ω h + α h²/2, ω += α h, the work integrals are
their power per unit speed times the angle travelled. The coefficients are taken from the
general solver the first time a (sign ω, sign F) pair is met and re-validated against the sign
pattern at every use; whenever the step would enter the band, change the sign of ω, or leave the
pattern, :meth:`SlavedAdvance.advance` returns None and the caller integrates numerically.
A viscous friction term (the friction-torque article's µ_1) makes the forces depend on the speed itself, so the
acceleration is no longer constant under held inputs: with it the step is always declined
(except at a constant prescribed speed, where the derivative is constant and one Euler step is
exact).  The differential-sliding torque is Coulomb-like (∝ load, sign of ω) and keeps it exact.

The coefficients of a (sign ω, sign F) pair are computed at a canonical point (|ω| = 100 band
speeds, |F| = 1 kN, α = 0), never at the point where the pair is first met: mathematically they
are the same everywhere outside the band, but computed at different points they would differ in
the last bits, and the steps would depend on history (an FMU state restored into a new
instance would then diverge).
"""

from __future__ import annotations

import math


class SlavedAdvance:
    """Exact step of a model with slaved carriers (see module docstring), either drive.

    Parameters
    ----------
    model : Model
        A quasi-static or kinematic model (``model.mechanism.zeta`` not None).
    """

    def __init__(self, model) -> None:
        mech = model.mechanism
        if mech.zeta is None:
            raise ValueError("SlavedAdvance needs a level with slaved carriers (quasi-static, kinematic)")
        self.model = model
        self.mech = mech
        # slowest sliding speed per unit screw speed [m/rad]: contacts, splines, bearings, loss
        factors = []
        laws = []               # the same, without the contact flanks when they have no friction
        for s, z in zip(mech.stages, mech.zeta):
            for fl in s.flanks:
                dx, dy, dz = fl.ax + z * fl.bx, fl.ay + z * fl.by, fl.az
                factors.append(math.sqrt(dx * dx + dy * dy + dz * dz))
                if mech.mu:
                    laws.append(factors[-1])
                if mech.mu3:
                    factors.append(fl.radius)     # differential sliding: sgñ(ω r)
                    laws.append(fl.radius)
            if s.e_spline:
                factors.append(s.spline_speed_factor)
                laws.append(s.spline_speed_factor)
            if s.g_bearing:
                factors.append(s.bearing_speed_factor)
                laws.append(s.bearing_speed_factor)
        if getattr(model, "coulomb_loss", False):
            factors.append(mech.c_out)
            laws.append(mech.c_out)
        #: sliding speed per unit screw speed [m/rad] of every regularised law that acts (the
        #: contact flanks only with µ_SR > 0: the kinematic level's contacts have no friction)
        self.law_factors = tuple(laws)
        #: a viscous term makes the forces depend on the speed: no closed-form step then
        self.viscous = mech.viscous or getattr(model, "viscous", False)
        #: screw speed [rad/s] above which every law is exactly Coulomb
        self.band_speed = mech.v_eps / min(factors)
        self._cache: dict = {}

    def _law(self, sign_w: float, sign_load: float):
        """Linear coefficients for this (sign ω, sign F), built from the general solver at the
        canonical point of the module docstring (so they do not depend on history)."""
        key = (sign_w, sign_load)
        if key in self._cache:
            return self._cache[key]
        mech = self.mech
        omega = sign_w * 100.0 * self.band_speed
        load = sign_load * 1000.0
        loss = self.model._extra_loss_torque(omega, load)
        cache = [None] * (2 * len(mech.stages))
        sol = mech.solve(omega, (), load, acceleration=0.0)
        rec = mech._sweep(omega, mech.carrier_speeds(omega, ()), load, 0.0, cache)
        if not sol.consistent or not mech._signs_hold(rec, 0.0):
            self._cache[key] = None
            return None
        (m0, m1), per_stage = rec
        checks = []
        for fi, a0, a1, co, x0, x1, h0, h1, b0, b1, e, g, sm, sb in per_stage:
            checks.append((a0 / load, a1, fi == 0))
            if e or g:
                checks.append((x0 / load, x1, sm > 0))
                checks.append((b0 / load, b1, sb > 0))
        wps = mech.carrier_speeds(omega, ())
        a_ref = 1000.0
        p_0 = mech._assemble(omega, wps, load, 0.0, rec, False).friction_power
        p_a = mech._assemble(omega, wps, load, a_ref, rec, False).friction_power
        speed = abs(omega)
        q_alpha = (p_a - p_0) / a_ref / speed
        q_load = p_0 / load / speed
        loss_per_load = abs(loss / load)      # kinematic level's Coulomb loss torque per |F|
        law = (m0 / load, m1, q_load, q_alpha, tuple(checks), loss_per_load)
        self._cache[key] = law
        return law

    def advance(self, x: list[float], u: tuple, h: float) -> list[float] | None:
        """State after a step h [s] with inputs u held, or None if not exact (see module doc).

        Torque drive: u = (motor torque [N·m], load [N]); speed drive: u = (prescribed screw
        acceleration [rad/s²], load [N]).
        """
        w0 = x[1]
        load = u[1]
        band = self.band_speed
        if abs(w0) < band or load == 0.0 or self.viscous:
            return None
        sign_w = 1.0 if w0 > 0.0 else -1.0
        law = self._law(sign_w, 1.0 if load > 0.0 else -1.0)
        if law is None:
            return None
        k_load, k_alpha, q_load, q_alpha, checks, loss_per_load = law
        loss = loss_per_load * abs(load) * sign_w
        if self.model.drive == "torque":
            torque = u[0]
            alpha = (torque - loss - k_load * load) / k_alpha
        else:
            alpha = u[0]
            torque = k_load * load + k_alpha * alpha + loss
        for c_load, c_alpha, positive in checks:
            if (c_load * load + c_alpha * alpha >= 0.0) != positive:
                return None
        w1 = w0 + alpha * h
        if w1 * sign_w < band:
            return None
        dth = (w0 + 0.5 * alpha * h) * h
        p_per_speed = q_load * load + q_alpha * alpha + loss_per_load * abs(load)
        return [x[0] + dth, w1, x[2] + torque * dth, x[3] + load * self.mech.c_out * dth,
                x[4] + p_per_speed * sign_w * dth]


class SlavedLevel:
    """Mixin for levels with slaved carriers: exposes the closed-form step to the steppers."""

    def _advance_law(self) -> SlavedAdvance:
        adv = self.__dict__.get("_slaved_advance")
        if adv is None:
            adv = self._slaved_advance = SlavedAdvance(self)
        return adv

    def smooth_breaks(self) -> tuple[float, ...]:
        """Screw speeds [rad/s] at which the rhs is only C¹ (steppers split their steps there).

        Zero and ±v_ε/f for every regularised law's sliding speed per unit screw speed f (a
        contact flank, spline, bearing or loss torque): there a sliding speed crosses zero or its
        band edge, where the law r(2 − r)µ|N| of friction.py meets its neighbour with equal value
        and slope but not curvature.  The largest is the band speed of :class:`SlavedAdvance`.
        """
        adv = self._advance_law()
        v_eps = self.mechanism.v_eps
        edges = sorted({v_eps / f for f in adv.law_factors if f > 0.0})
        return tuple([-e for e in reversed(edges)] + [0.0] + edges)

    def closed_form_advance(self, t: float, x: list[float], u: tuple, h: float) -> list[float] | None:
        """State after a step h [s] in closed form, or None where it is not exact.

        Speed drive at constant speed (prescribed acceleration 0): the derivative is constant
        over the step, so one Euler step is exact.  Otherwise :class:`SlavedAdvance`.
        """
        if self.drive == "speed" and u[0] == 0.0:
            return [xi + h * di for xi, di in zip(x, self.rhs(t, x, u))]
        return self._advance_law().advance(x, u, h)
