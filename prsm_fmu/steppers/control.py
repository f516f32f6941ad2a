"""Shared machinery of the adaptive steppers: tolerances, error weights, the first-step norms,
the elementary step-size controller (memory: the proposal for the next internal step), the
landing on the friction law's kinks and the slip error norm (:func:`slip_error`, ROS34PW2's).

Kink landing: a model may report ``sliding_velocities(x)`` (one tuple of components [m/s] per
regularised friction law) and ``kink_speeds`` (per law the sliding speeds [m/s] where the law is
only C¹: v_ε, and 0 for a one-component law).  After each trial step the adaptive steppers ask
:func:`kink_fraction` whether the step crosses a kink or changes a sliding speed faster than
the law resolves, and if so retry it cut to that fraction (counted as a rejection; at most
:data:`MAX_KINK_CUTS` per internal step); after a landing the next step resumes the size the cut
shortened.  No embedded error estimate then spans a kink (docs/accuracy.md, "Landing on the
friction law's kinks")."""

from __future__ import annotations

import math
from typing import Any, Sequence

from .base import Stepper, _INF, _check_count, _check_tol, _model_mask, _model_scale

__all__ = ["AdaptiveBase", "KinkLanding", "KINK_BAND", "APPROACH", "MAX_KINK_CUTS", "kink_fraction",
           "model_kinks", "slip_error"]

#: a memory's end time matches the next advance's start within this many ulps of max(|t|, h)
_TIME_MATCH = 4e-16

#: a sliding speed within this fraction of the friction band's speed v_ε (the smallest positive
#: kink speed) of a kink counts as on it: a step that starts there is not cut for that kink (it
#: leaves it), one that ends there has landed on it.  The law's curvature jump acts over that
#: distance only, so what a step within it misses is below (1e-3)² of the law's curvature term
KINK_BAND = 1e-3

#: the friction law's resolution: between its kinks, Coulomb's s/|s| has k-th derivatives of
#: order 1/|s|^k, so a step may change a sliding speed |s| by at most this fraction of
#: max(|s|, v_ε), |s| the smaller of its ends (approaching zero speed: at most halving it)
APPROACH = 1.0

#: secant cuts of one internal step towards a kink before the step is taken as it is (the
#: secant on the sliding velocities converges in one or two where they are smooth in time)
MAX_KINK_CUTS = 4


def kink_fraction(v0: Sequence[tuple], v1: Sequence[tuple], kinks: Sequence[tuple],
                  band: float) -> float | None:
    """Where a step should end so that it neither crosses a kink of a friction law nor changes a
    sliding speed faster than the law resolves: the fraction of the step in (0, 1), or None.

    Along the step the sliding velocities are taken linear in time, s(θ) = s0 + θ (s1 − s0)
    (secant through the step's ends).  Kinks: the roots θ of |s(θ)| = k for each kink speed
    k > 0 of the law, and of s(θ) = 0 for the kink 0 of a one-component law, that lie more than
    the landing band (:data:`KINK_BAND` · v_ε, as distance travelled) from both ends.
    Resolution: where |s| changes by more than :data:`APPROACH` · max(v_ε, r) — r = |s0| when
    it grows, |s0|/(1 + APPROACH) when it falls (at most halving it on the way to zero) — the
    fraction that keeps the change within that.

    Parameters
    ----------
    v0, v1 : sequence of tuple of float
        Sliding velocities [m/s] at the step's start and at the trial end, one tuple per law.
    kinks : sequence of tuple of float
        Per law, its kink speeds [m/s] (0 for a sign change of a one-component law).
    band : float
        v_ε [m/s], the friction band's speed (> 0).

    Returns
    -------
    float or None
        The smallest such fraction, or None if the step may stand.
    """
    tol = KINK_BAND * band
    best = 2.0
    for s0, s1, ks in zip(v0, v1, kinks):
        if len(s0) == 1:
            a0, a1 = s0[0], s1[0]
            d = a1 - a0
            dn = abs(d)
            if not dn > tol:
                continue
            r0, r1 = abs(a0), abs(a1)
            if a0 * a1 <= 0.0 or r0 <= band or r1 <= band:
                # the segment reaches 0 or the band: its roots (else there are none in it)
                for k in ks:
                    for root in ((k - a0) / d, (-k - a0) / d) if k else (-a0 / d,):
                        if 0.0 < root < 1.0 and root * dn > tol and (1.0 - root) * dn > tol \
                                and root < best:
                            best = root
        else:
            x0, y0, z0 = s0
            dx, dy, dz = s1[0] - x0, s1[1] - y0, s1[2] - z0
            aa = dx * dx + dy * dy + dz * dz
            dn = math.sqrt(aa)
            if not dn > tol:
                continue
            rr0 = x0 * x0 + y0 * y0 + z0 * z0
            r0 = math.sqrt(rr0)
            r1 = math.sqrt(s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2])
            if r0 + r1 - dn <= 2.0 * band:
                # |s| may reach the band on the way (it stays above (r0 + r1 − dn)/2)
                b = x0 * dx + y0 * dy + z0 * dz
                for k in ks:
                    if not k:
                        continue
                    disc = b * b - aa * (rr0 - k * k)
                    if disc < 0.0:
                        continue
                    sq = math.sqrt(disc)
                    for root in ((-b - sq) / aa, (-b + sq) / aa):
                        if 0.0 < root < 1.0 and root * dn > tol and (1.0 - root) * dn > tol \
                                and root < best:
                            best = root
        change = abs(r1 - r0)
        limit = APPROACH * max(band, r0 / (1.0 + APPROACH) if r1 < r0 else r0)
        if change > limit and limit / change < best:
            best = limit / change
    return best if best < 1.0 else None


def slip_error(ds: Sequence[tuple], s0: Sequence[tuple], rtol: float, atol: float,
               band: float) -> float:
    """The largest weighted error of a step's sliding velocities (the slip error norm).

    A friction force follows its sliding velocity s through the law's direction s/|s| and
    magnitude, so its relative error is about |Δs| / max(|s|, v_ε): inside the band the law is
    linear in s/v_ε, outside it the direction turns by |Δs|/|s|.  Where the thread contact
    rolls almost purely, s = ω a + ω_P b is a small difference of the screw's and the carrier's
    parts (near zero speed |ω_P b| ≈ 4.5 |s| for Li et al. (2021)'s stage 1), so an error in
    the carrier speed within its own weight rtol·|ω_P| moves the forces several times as much
    (docs/accuracy.md, "The slip error norm").  Weight of a law: atol·v_ε + rtol·max(|s|, v_ε).

    Parameters
    ----------
    ds : sequence of tuple of float
        The error estimate's sliding velocities [m/s] (``sliding_velocities`` of the estimate's
        state vector: the velocities are linear in the speeds), one tuple per law.
    s0 : sequence of tuple of float
        The sliding velocities [m/s] at the step's start.
    rtol, atol : float
        The stepper's tolerances (atol relative to v_ε here).
    band : float
        v_ε [m/s].

    Returns
    -------
    float
        max over the laws of |Δs| / weight (0 without laws; nan propagates only through the
        state norm, which the same estimate makes nan).
    """
    worst = 0.0
    floor = atol * band
    for d, s in zip(ds, s0):
        if len(d) == 1:
            dn, sn = abs(d[0]), abs(s[0])
        else:
            dn = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
            sn = math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        e = dn / (floor + rtol * max(sn, band))
        if e > worst:
            worst = e
    return worst


def model_kinks(model: Any) -> tuple:
    """What a model reports of its friction laws' kinks (docs/accuracy.md, "Landing on the
    friction law's kinks").

    Parameters
    ----------
    model : OdeModel
        A model that may have ``sliding_velocities(x)`` and ``kink_speeds``.

    Returns
    -------
    tuple
        ``(speeds, kinks, band)``: the model's ``sliding_velocities`` (None if it reports no
        sliding velocities or no positive kink speed: no landing), its ``kink_speeds`` [m/s]
        and v_ε [m/s], the smallest positive kink speed (0.0 without one).
    """
    speeds = getattr(model, "sliding_velocities", None)
    kinks = tuple(getattr(model, "kink_speeds", ()) or ()) if callable(speeds) else ()
    positive = [abs(k) for ks in kinks for k in ks if k != 0.0]
    return (speeds if kinks and positive else None, kinks,
            min(positive) if positive else 0.0)


class KinkLanding:
    """One advance's landing on the kinks of a model's friction laws (module docstring).

    Holds the sliding velocities at the current accepted point, the cuts of the internal step
    being tried and the step size [s] the first cut shortened.

    Parameters
    ----------
    speeds : callable
        The model's ``sliding_velocities(x)``.
    kinks : tuple of tuple of float
        The model's ``kink_speeds`` [m/s].
    band : float
        v_ε [m/s].
    h_min : float
        Smallest internal step [s]: no cut below it.
    """

    __slots__ = ("speeds", "kinks", "band", "h_min", "v0", "v_new", "cuts", "h_uncut")

    def __init__(self, speeds: Any, kinks: tuple, band: float, h_min: float) -> None:
        self.speeds, self.kinks, self.band, self.h_min = speeds, kinks, band, h_min
        self.v0 = self.v_new = None
        self.cuts = 0
        self.h_uncut = 0.0

    def start(self, y: Sequence[float]) -> list:
        """The sliding velocities [m/s] at the accepted point ``y`` the next trial starts from
        (computed once per point)."""
        if self.v0 is None:
            self.v0 = self.speeds(y)
        return self.v0

    def cut(self, y: Sequence[float], y_new: Sequence[float], h_step: float,
            stats: Any) -> float | None:
        """The size [s] to retry a trial step from ``y`` to ``y_new`` of size ``h_step`` with,
        if it must end on a kink (:func:`kink_fraction`: no error estimate holds across one),
        counted in ``stats.rejected``; else None, as well once :data:`MAX_KINK_CUTS` cuts were
        made or below ``h_min``."""
        self.v_new = None
        if self.cuts >= MAX_KINK_CUTS:
            return None
        if self.v0 is None:
            self.v0 = self.speeds(y)
        self.v_new = self.speeds(y_new)
        s = kink_fraction(self.v0, self.v_new, self.kinks, self.band)
        if s is None or h_step * s < self.h_min:
            return None
        if not self.cuts:
            self.h_uncut = h_step
        self.cuts += 1
        stats.rejected += 1
        return h_step * s

    def accepted(self, h_new: float, fac: float) -> float:
        """The next step's size [s] after an accepted one whose controller proposed ``h_new``
        with factor ``fac``: after a landing the size the cut shortened (the controller chose it
        on the smooth side), unless the controller asks for less."""
        if self.cuts:
            if fac >= 1.0:
                h_new = max(h_new, self.h_uncut)
            self.cuts = 0
        self.v0 = self.v_new
        return h_new

    def rejected(self) -> None:
        """A trial failed its error test: no return to the uncut size after it."""
        self.h_uncut = 0.0


def _finite_floats(v: Any, n: int | None) -> bool:
    """Whether ``v`` is a tuple of ``n`` (any number if None) finite floats (a memory's part)."""
    return (isinstance(v, tuple) and (n is None or len(v) == n)
            and all(isinstance(e, float) and math.isfinite(e) for e in v))


class AdaptiveBase(Stepper):
    """Common tolerance handling, error norm and step-size controller."""

    #: exponent denominator of the controller: err ~ h**(q+1), q = min(order, embedded order)
    _q1: float = 1.0

    def __init__(
        self,
        model: Any,
        rtol: float,
        atol: float,
        h_min: float,
        max_substeps: int,
        fixed_substeps: int | None,
        safety: float,
        fac_min: float,
        fac_max: float,
    ) -> None:
        super().__init__(model)
        n = self.n_states
        self.rtol = _check_tol("rtol", rtol, strictly_positive=False)
        self.atol = _check_tol("atol", atol, strictly_positive=True)
        self.h_min = _check_tol("h_min", h_min, strictly_positive=True)
        self.max_substeps = _check_count("max_substeps", max_substeps, 1)
        self.fixed_substeps = (
            None if fixed_substeps is None else _check_count("fixed_substeps", fixed_substeps, 1)
        )
        if not (0.0 < safety <= 1.0):
            raise ValueError(f"safety = {safety!r} is out of range: must be in (0, 1]")
        if not (0.0 < fac_min < 1.0):
            raise ValueError(f"fac_min = {fac_min!r} is out of range: must be in (0, 1)")
        if not (1.0 < fac_max < _INF):
            raise ValueError(f"fac_max = {fac_max!r} is out of range: must be finite and > 1")
        self.safety = float(safety)
        self.fac_min = float(fac_min)
        self.fac_max = float(fac_max)
        self.state_scale = _model_scale(model, n)
        self.error_mask = _model_mask(model, n)
        # absolute error weights; excluded states get an infinite weight, so they add 0
        # to the norm (while a non-finite error in them still shows up as nan)
        self._atol_w = [self.atol * s if m else _INF for s, m in zip(self.state_scale, self.error_mask)]
        self._n_err = sum(self.error_mask)
        self._h_prop: float | None = None

        #: the model's sliding velocities (None: no kink landing), their kink speeds [m/s] and
        #: the friction band's speed v_ε [m/s] (:func:`model_kinks`)
        self._speeds, self._kinks, self._band = model_kinks(model)

    # --- memory ---------------------------------------------------------------------

    def get_memory(self) -> tuple:
        """Return ``(h_proposal,)``: the step size [s] proposed for the next internal
        step (``None`` before the first adaptive advance or after :meth:`reset`)."""
        return (self._h_prop,)

    def set_memory(self, m: tuple) -> None:
        """Restore ``(h_proposal,)`` from :meth:`get_memory`."""
        m = tuple(m)
        if len(m) != 1 or not (m[0] is None or (isinstance(m[0], float) and 0.0 < m[0] < _INF)):
            raise ValueError(
                f"{self.name}: memory must be (h_proposal,) with None or a finite float > 0, got {m!r}"
            )
        self._h_prop = m[0]

    def reset(self) -> None:
        """Forget the step-size proposal."""
        self._h_prop = None

    # --- continuation: an advance that starts where the last one ended, inputs unchanged ---

    def _continues(self, t: float, x: Sequence[float], u: tuple, h: float) -> float | None:
        """The last advance's final proposal [s] if this one continues it (its end time, state
        and inputs), else None (also before the first advance).  Reads ``self._cont``, the
        ``(t_end, x_end, u, h_next)`` that :meth:`_continuation` made."""
        c = getattr(self, "_cont", None)
        if c is None or abs(t - c[0]) > _TIME_MATCH * max(abs(t), h) or c[2] != tuple(u):
            return None
        return c[3] if c[1] == tuple(x) else None

    @staticmethod
    def _continuation(t_end: float, x: Sequence[float], u: Sequence[float],
                      h_next: float) -> tuple:
        """The record :meth:`_continues` compares with: end time [s], state and inputs of an
        advance, and the step [s] proposed after its last step, as plain floats."""
        return (t_end, tuple(x), tuple(float(v) for v in u), h_next)

    def _check_continuation(self, cont: Any) -> None:
        """Refuse a memory's continuation that is neither None nor ``(t_end, x_end, u,
        h_next)`` with finite floats and ``h_next > 0`` [s]."""
        if cont is None:
            return
        floats = _finite_floats
        ok = isinstance(cont, tuple) and len(cont) == 4
        if ok:
            t_end, x_end, u, h_next = cont
            ok = (isinstance(t_end, float) and math.isfinite(t_end)
                  and floats(x_end, self.n_states) and floats(u, None)
                  and isinstance(h_next, float) and 0.0 < h_next < _INF)
        if not ok:
            raise ValueError(f"{self.name}: memory's continuation must be None or (t_end, "
                             f"x_end, u, h_next) with {self.n_states} finite states, finite "
                             f"inputs and h_next > 0 [s], got {cont!r}")

    # --- helpers --------------------------------------------------------------------

    def _initial_step(self, x: Sequence[float], f0: Sequence[float], h: float) -> float:
        """Cheap first-step guess [s] without extra rhs calls, after Hairer, Norsett &
        Wanner, Solving ODEs I, Sec. II.4 (first part only): ``0.01 * max(d0, 1) / d1``
        with ``d0``, ``d1`` the weighted RMS norms of ``x`` and ``f(t, x)``, at most ``h``."""
        _, d0, d1 = self._start_norms(x, f0)
        if not d1 > 1e-5:  # practically at rest (or nan, handled by the step itself)
            return h
        return min(h, 0.01 * max(d0, 1.0) / d1)

    def _start_norms(self, x: Sequence[float], f0: Sequence[float]) -> tuple:
        """Error weights at ``x`` and the weighted RMS norms of ``x`` and ``f0`` (Hairer,
        Norsett & Wanner's d0, d1)."""
        rtol = self.rtol
        w = [at + rtol * abs(a) for a, at in zip(x, self._atol_w)]
        d0 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(x, w)]) / self._n_err)
        d1 = math.sqrt(sum([(a / wi) ** 2 for a, wi in zip(f0, w)]) / self._n_err)
        return w, d0, d1

    def _landing(self) -> KinkLanding | None:
        """A fresh :class:`KinkLanding` for an adaptive advance, None if the model reports no
        sliding velocities (or landing is off)."""
        if self._speeds is None:
            return None
        return KinkLanding(self._speeds, self._kinks, self._band, self.h_min)

    def _factor(self, err: float) -> float:
        """Step-size ratio proposed by the elementary controller for error norm ``err``."""
        if err == 0.0:
            return self.fac_max
        if not err < _INF:
            return self.fac_min
        return min(self.fac_max, max(self.fac_min, self.safety * err ** (-1.0 / self._q1)))
