"""The saturation QP solved in compiled code: Goldfarb and Idnani's dual active-set method.

The problem of :mod:`lapwrench.motion.saturation` (its first, all-hard level):

    min_a ½ (a - a₀)ᵀ M (a - a₀)   s.t.   E a = E a₀,   lo - w <= C a <= hi + w,

with M positive definite, E the primary task's rows (independent), C the limit rows and w each
row's widening (``BOX_WIDENING`` of its scale). a₀ meets the equalities, so it is the optimum
with only the equalities active, which is where the dual method starts (Goldfarb & Idnani, "A
numerically stable dual method for solving strictly convex quadratic programs", Math. Prog. 27,
1983). Each inequality is written nᵢᵀ a >= bᵢ (the lower side of row i: n = Cᵢ, b = loᵢ - wᵢ; the
upper side: n = -Cᵢ, b = -hiᵢ - wᵢ). With the active normals N (the equalities first) and their
multipliers u, each iteration takes the most violated constraint p (violation in units of its
row's scale) and moves along

    r = (Nᵀ M⁻¹ N)⁻¹ Nᵀ M⁻¹ n_p,      z = M⁻¹ (n_p - N r),

which keeps every active constraint and raises n_pᵀ a. The KKT condition M (a - a₀) = N u + n_p u_p
holds throughout with a += t z, u -= t r, u_p += t. The step t is the smaller of

* t₂ = (b_p - n_pᵀ a) / (zᵀ n_p), the full step, after which p joins the active set, and
* t₁ = min uⱼ / rⱼ over active inequalities with rⱼ > 0, after which constraint j leaves it
  (its multiplier would turn negative) and p is tried again.

If z = 0 (n_p depends on the active normals) only the dual step is taken; with no t₁ either, the
problem is infeasible. The solution is reached when nothing is violated. quadprog implements the
same method with updated factorisations; here the small systems (at most 7 x 7) are solved afresh
by Cholesky each iteration, which for 7 joints costs a few µs in all and needs no Python.
"""

from __future__ import annotations

import numpy as np

from lapwrench.jit import kernel
from lapwrench.spatial import Mat, Vec, cholesky_factor, inner

QP_SOLVED = 0
QP_INFEASIBLE = 1
QP_ITERATION_LIMIT = 2
QP_NUMERICAL = 3  # the active normals became dependent (round-off): the caller falls back to quadprog

# A constraint counts as violated when it is off by more than this fraction of its row's scale
# (the rows are widened by 1e-7 of their scale, so a solution that meets this meets the true bounds).
VIOLATION_TOL = 1e-12
# n_p counts as dependent on the active normals when zᵀ n_p falls below this fraction of n_pᵀ M⁻¹ n_p.
DEPENDENCE_TOL = 1e-10


@kernel
def cholesky_solve(S: Mat, rhs: Vec, L: Mat, x: Vec) -> bool:
    """Solve S x = rhs in place for a symmetric positive definite S (q x q) by Cholesky, with ``L``
    (at least q x q) as workspace; False if S is not positive definite."""
    q = S.shape[0]
    if not cholesky_factor(S, L, 1e-14):
        return False
    for i in range(q):  # L y = rhs, y stored in x
        v = rhs[i]
        for c in range(i):
            v -= L[i, c] * x[c]
        x[i] = v / L[i, i]
    for i in range(q - 1, -1, -1):  # Lᵀ x = y
        v = x[i]
        for c in range(i + 1, q):
            v -= L[c, i] * x[c]
        x[i] = v / L[i, i]
    return True


@kernel
def dual_active_set(
    Minv: Mat, a0: Vec, E: Mat, C: Mat, lo: Vec, hi: Vec, widen: Vec, scale: Vec, max_iter: int
) -> tuple[Vec, int]:
    """min ½ (a - a₀)ᵀ M (a - a₀) s.t. E a = E a₀ and lo - widen <= C a <= hi + widen (module docstring).

    Args:
        Minv: M⁻¹ (n x n), M symmetric positive definite.
        a0: The unconstrained optimum (n); it must meet the equalities.
        E: Equality rows (k x n), independent.
        C: Inequality rows (m x n); ``lo``, ``hi``, ``widen``, ``scale`` per row (m).
        max_iter: Iteration cap (each adds or drops one constraint).

    Returns:
        (a, status): ``QP_SOLVED``, or ``QP_INFEASIBLE`` / ``QP_ITERATION_LIMIT`` / ``QP_NUMERICAL``
        with ``a`` the last iterate (not to be used).
    """
    n, k, m = a0.shape[0], E.shape[0], C.shape[0]
    total = k + 2 * m
    # every constraint as nᵀ a >= b: the equalities, then the rows' lower and upper sides;
    # P holds M⁻¹ n for each (small loops: BLAS calls cost more than the arithmetic at this size)
    normals = np.empty((total, n))
    b = np.empty(total)
    row_scale = np.ones(total)
    for i in range(total):
        src = E[i] if i < k else (C[i - k] if i < k + m else C[i - k - m])
        sign = -1.0 if i >= k + m else 1.0
        for c in range(n):
            normals[i, c] = sign * src[c]
    for i in range(k):
        b[i] = inner(E[i], a0)
    for i in range(m):
        b[k + i] = lo[i] - widen[i]
        b[k + m + i] = -hi[i] - widen[i]
        row_scale[k + i] = row_scale[k + m + i] = scale[i]
    P = np.zeros((total, n))
    for i in range(total):
        for r_ in range(n):
            acc = 0.0
            for c in range(n):
                acc += Minv[r_, c] * normals[i, c]
            P[i, r_] = acc
    active = np.empty(n + 1, dtype=np.int64)
    u = np.zeros(n + 1)
    is_active = np.zeros(total, dtype=np.bool_)
    for j in range(k):
        active[j] = j
        is_active[j] = True
    q = k
    a = a0.copy()
    S = np.empty((n + 1, n + 1))
    L = np.empty((n + 1, n + 1))
    rhs = np.empty(n + 1)
    r = np.empty(n + 1)
    z = np.empty(n)
    for _ in range(max_iter):
        # the most violated inequality
        p, worst = -1, VIOLATION_TOL
        for i in range(k, total):
            if not is_active[i]:
                v = (b[i] - inner(normals[i], a)) / row_scale[i]
                if v > worst:
                    p, worst = i, v
        if p < 0:
            return a, QP_SOLVED
        n_p = normals[p]
        np_Minv_np = inner(n_p, P[p])
        u_p = 0.0
        while True:  # steps on p until it joins the active set
            for i in range(q):
                rhs[i] = inner(P[active[i]], n_p)
                for j in range(q):
                    S[i, j] = inner(normals[active[i]], P[active[j]])
            if not cholesky_solve(S[:q, :q], rhs[:q], L, r):
                return a, QP_NUMERICAL
            for c in range(n):
                v = P[p, c]
                for j in range(q):
                    v -= r[j] * P[active[j], c]
                z[c] = v
            curvature = inner(z, n_p)
            # with n independent normals active, n_p depends on them whatever round-off says
            full = q < n and curvature > DEPENDENCE_TOL * np_Minv_np
            t1, drop = np.inf, -1
            for j in range(k, q):
                if r[j] > 0.0 and u[j] / r[j] < t1:
                    t1, drop = u[j] / r[j], j
            t2 = (b[p] - inner(n_p, a)) / curvature if full else np.inf
            if drop < 0 and not full:
                return a, QP_INFEASIBLE
            t = min(t1, t2)
            if full:
                for c in range(n):
                    a[c] += t * z[c]
            for j in range(q):
                u[j] -= t * r[j]
            u_p += t
            if full and t2 <= t1:
                active[q], u[q] = p, u_p
                is_active[p] = True
                q += 1
                break
            # constraint ``drop`` leaves the active set; p is tried again
            is_active[active[drop]] = False
            for j in range(drop, q - 1):
                active[j], u[j] = active[j + 1], u[j + 1]
            q -= 1
            if not np.isfinite(t):
                return a, QP_NUMERICAL
    return a, QP_ITERATION_LIMIT
