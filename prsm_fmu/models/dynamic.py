"""Dynamic level: the Lagrange model of Li et al. (2021) §2 with one degree of freedom per carrier.

Generalized coordinates: the screw angle and the carrier angles (Li et al. (2021) Eq. 21).  The carriers
are driven only by screw–roller friction; their time constants are ~0.01–0.5 ms, so the system
is stiff: use the Rosenbrock stepper, or an explicit one with steps below the limit printed by
``benchmarks/step_cost.py``.  simulate and the FMU use the Rosenbrock stepper with the options
of ``simulate.TUNED_OPTIONS`` (Jacobian reuse, a first step bounded by the stiffness), which gave
the cheapest 1 ms steps at the reference solver's error.  Derivation: docs/model.md §3.
"""

from __future__ import annotations

from .base import Model


class DynamicModel(Model):
    """Rigid-body dynamic model with carrier dynamics (states: module docstring of base)."""

    fidelity = "dynamic"
    carriers = "dynamic"

    def analytic_jacobian(self, t: float, x: list[float], u: tuple) -> list[list[float]]:
        """d rhs / d x at (t, x, u), from the recursion's own derivatives.

        :meth:`prsm_fmu.mechanics.Mechanism.rates_jacobian` differentiates the balances with
        the sign pattern of the solution held (exact wherever the pattern does not change at
        x); the screw angle and the work integrals appear in no derivative, so their columns
        are zero.  tests/test_jacobian.py checks it against central differences of
        :meth:`rhs`.

        It is deliberately not called ``jacobian`` (the name the steppers pick up by
        default): in plain Python it costs about six rhs calls against the three of the
        forward-difference Jacobian the W-method is content with (benchmarks/step_cost.py
        prints both), so the steppers keep the differences unless a caller asks for it.

        Parameters
        ----------
        t : float
            Time [s] (unused: the model is autonomous).
        x : list of float
            State (layout: module docstring of base).
        u : tuple
            Inputs held over the step.

        Returns
        -------
        list of list of float
            Row-major n × n matrix [SI units of d state_i/dt per unit of state_j].
        """
        load = u[1]
        mech = self.mechanism
        omega = x[1]
        nc = self.n_carrier_states
        ie = self._i_energy
        if self._torque_drive:
            (_, motor, _, _), dalpha, dmotor, dacc, dpf = mech.rates_jacobian(
                omega, x[2:ie], load, u[0])
            motor = u[0]
            dw_in = [0.0] * (nc + 1)
            dw_in[0] = motor
        else:
            (_, motor, _, _), dalpha, dmotor, dacc, dpf = mech.rates_jacobian(
                omega, x[2:ie], load, acceleration=u[0])
            dw_in = [d * omega for d in dmotor]
            dw_in[0] += motor
        n = self.n_states
        pad_left, pad_right = [0.0], [0.0] * (n - 2 - nc)
        theta = [0.0] * n
        theta[1] = 1.0
        rows = [theta, pad_left + dalpha + pad_right]
        rows += [pad_left + d + pad_right for d in dacc]
        w_out = [0.0] * n
        w_out[1] = load * mech.c_out
        rows += [pad_left + dw_in + pad_right, w_out, pad_left + dpf + pad_right]
        return rows
