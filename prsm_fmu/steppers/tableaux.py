"""Coefficients of the Runge-Kutta and Rosenbrock methods, as data, and the coefficients the
steppers derive from them once at import (error weights, the transformed Rosenbrock form).

The order conditions of every tableau are checked in tests/test_steppers.py.
"""

from __future__ import annotations

from typing import Sequence

__all__ = ["EXPLICIT_TABLEAUS", "ROS_GAMMA", "ROS_ALPHA", "ROS_GAMMA_IJ", "ROS_B", "ROS_BHAT"]

# Dormand & Prince (1980), "A family of embedded Runge-Kutta formulae", J. Comput. Appl.
# Math. 6, 19-26; tableau as in Hairer, Norsett & Wanner, Solving ODEs I, Table II.5.2.
_DP_C = (0.0, 1 / 5, 3 / 10, 4 / 5, 8 / 9, 1.0, 1.0)
_DP_A = (
    (),
    (1 / 5,),
    (3 / 40, 9 / 40),
    (44 / 45, -56 / 15, 32 / 9),
    (19372 / 6561, -25360 / 2187, 64448 / 6561, -212 / 729),
    (9017 / 3168, -355 / 33, 46732 / 5247, 49 / 176, -5103 / 18656),
    (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84),
)
_DP_B = (35 / 384, 0.0, 500 / 1113, 125 / 192, -2187 / 6784, 11 / 84, 0.0)
_DP_BHAT = (5179 / 57600, 0.0, 7571 / 16695, 393 / 640, -92097 / 339200, 187 / 2100, 1 / 40)

# Bogacki & Shampine (1989), "A 3(2) pair of Runge-Kutta formulas", Appl. Math. Lett.
# 2(4), 321-325.
_BS_C = (0.0, 1 / 2, 3 / 4, 1.0)
_BS_A = ((), (1 / 2,), (0.0, 3 / 4), (2 / 9, 1 / 3, 4 / 9))
_BS_B = (2 / 9, 1 / 3, 4 / 9, 0.0)
_BS_BHAT = (7 / 24, 1 / 4, 1 / 3, 1 / 8)

# error weights b - b_hat (DP: without the zero entry of stage 2)
_DP_E = tuple(b - bh for i, (b, bh) in enumerate(zip(_DP_B, _DP_BHAT)) if i != 1)
_BS_E = tuple(b - bh for b, bh in zip(_BS_B, _BS_BHAT))

#: explicit tableaus by order: (c, a, b, b_hat) -- exposed for the order tests
EXPLICIT_TABLEAUS = {5: (_DP_C, _DP_A, _DP_B, _DP_BHAT), 3: (_BS_C, _BS_A, _BS_B, _BS_BHAT)}


# ROS34PW2: J. Rang and L. Angermann, "New Rosenbrock W-methods of order 3 for partial
# differential algebraic equations of index 1", BIT Numer. Math. 45 (2005) 761-787.
# 4 stages, order 3 with an embedded order-2 solution; L-stable (R(inf) = 0), stiffly
# accurate (b = last row of alpha + gamma), embedded solution A-stable; satisfies the
# Prothero-Robinson conditions (less order reduction for stiff forced problems).  The
# coefficients are checked in tests/test_steppers.py against the Rosenbrock order
# conditions (Hairer & Wanner, Solving ODEs II, Table IV.7.1) and by observed order.
# Formulation: k_i from (I - h gamma J) k_i = h f(x + sum_j alpha_ij k_j) + h J sum_j gamma_ij k_j.
ROS_GAMMA = 4.3586652150845900e-01
ROS_ALPHA = (
    (0.0, 0.0, 0.0, 0.0),
    (8.7173304301691801e-01, 0.0, 0.0, 0.0),
    (8.4457060015369423e-01, -1.1299064236484185e-01, 0.0, 0.0),
    (0.0, 0.0, 1.0, 0.0),
)
ROS_GAMMA_IJ = (  # strictly lower part; the diagonal is ROS_GAMMA
    (0.0, 0.0, 0.0, 0.0),
    (-8.7173304301691801e-01, 0.0, 0.0, 0.0),
    (-9.0338057013044082e-01, 5.4180672388095326e-02, 0.0, 0.0),
    (2.4212380706095346e-01, -1.2232505839045147e00, 5.4526025533510214e-01, 0.0),
)
ROS_B = (2.4212380706095346e-01, -1.2232505839045147e00, 1.5452602553351020e00, 4.3586652150845900e-01)
ROS_BHAT = (3.7810903145819369e-01, -9.6042292212423178e-02, 0.5, 2.1793326075422950e-01)


def _ros_transformed() -> tuple:
    """Coefficients of the Jacobian-product-free form (Hairer & Wanner II, (IV.7.25)):
    with u_i = sum_j Gamma_ij k_j (Gamma incl. its diagonal),
    (I/(h gamma) - J) u_i = f(x + sum_j a_ij u_j) + sum_j (c_ij / h) u_j,
    x_new = x + sum_i m_i u_i, where a = alpha Gamma^-1, c = diag(1/gamma) - Gamma^-1,
    m = b^T Gamma^-1."""
    s = 4
    g = [
        [ROS_GAMMA_IJ[i][j] if j < i else (ROS_GAMMA if i == j else 0.0) for j in range(s)]
        for i in range(s)
    ]
    ginv = [[0.0] * s for _ in range(s)]
    for j in range(s):  # forward substitution for the columns of the lower-triangular inverse
        for i in range(j, s):
            acc = 1.0 if i == j else 0.0
            for k in range(j, i):
                acc -= g[i][k] * ginv[k][j]
            ginv[i][j] = acc / g[i][i]
    a = [[sum(ROS_ALPHA[i][k] * ginv[k][j] for k in range(s)) for j in range(s)] for i in range(s)]
    c = [[-ginv[i][j] if j < i else 0.0 for j in range(s)] for i in range(s)]
    m = [sum(ROS_B[k] * ginv[k][j] for k in range(s)) for j in range(s)]
    mhat = [sum(ROS_BHAT[k] * ginv[k][j] for k in range(s)) for j in range(s)]
    alpha_sum = [sum(row) for row in ROS_ALPHA]
    return a, c, m, mhat, alpha_sum


_ROS_A, _ROS_C, _ROS_M, _ROS_MHAT, _ROS_ALPHA_SUM = _ros_transformed()
# flat coefficients for the hot loop: a_ij, c_ij (i > j) and the stage times alpha_i
_ROS_TRIAL = (
    tuple(_ROS_A[i][j] for i in range(1, 4) for j in range(i))
    + tuple(_ROS_C[i][j] for i in range(1, 4) for j in range(i))
    + tuple(_ROS_ALPHA_SUM[1:])
)
_ROS_E = tuple(p - q for p, q in zip(_ROS_M, _ROS_MHAT))  # error weights m - m_hat


def _quadrature_weights(c: Sequence[Sequence[float]], gamma: float, m: Sequence[float]) -> tuple:
    """Weights w with ``sum_i m_i u_q,i = h sum_i w_i (f_q(X_i) + J_qd u_d,i)`` for the
    quadrature states q of a Rosenbrock method in the transformed form.

    Their stage equations ``u_q,i / (h gamma) - J_qd u_d,i = f_q(X_i) + sum_j (c_ij / h) u_q,j``
    give ``u_q = gamma (I - gamma C)^-1 g`` with ``g_i = h (f_q(X_i) + J_qd u_d,i)`` (C strictly
    lower triangular), so ``w = gamma m^T (I - gamma C)^-1`` (back substitution)."""
    s = len(m)
    w = [0.0] * s
    for j in range(s - 1, -1, -1):
        w[j] = gamma * (m[j] + sum(w[i] * c[i][j] for i in range(j + 1, s)))
    return tuple(w)


# result and error weights of the quadrature states (see _quadrature_weights)
_ROS_WQ = _quadrature_weights(_ROS_C, ROS_GAMMA, _ROS_M)
_ROS_EQ = _quadrature_weights(_ROS_C, ROS_GAMMA, _ROS_E)
