"""Slow, plain references that do not trust the solver's code (as stumpy keeps tests/naive.py).

* The actuator from first principles: p = dU/dV of Eqs. (2.1)–(2.6), differentiated
  numerically, inverted with ``scipy.optimize.brentq``.
* Rest strains by plain loops over the tubes.
* The planar rod as a scipy ``solve_bvp`` multipoint problem in a *different* formulation:
  state (x, y, θ, n_x, n_y, m) in every section, n integrated from n' = −f instead of being
  taken from global equilibrium, sections coupled by junction conditions (endplate weight as
  a force jump), clamped base and loaded free tip as two-point boundary conditions — the
  layout of the thesis's Appendix A.2 MATLAB code.
* The fold scan visiting every interval of its grid (the solver's stops early).
* The predictor's rest-strain gradient by forward sensitivities, one linearised system per
  parameter (the solver's kernel takes the discrete adjoint of the same scheme).
* The 3D contact Newton's textbook iteration: a residual pass for every trial of the line
  search, then a Jacobian pass at the accepted trial (the kernel forms a first trial's
  residual with its Jacobian where the iteration before accepted its first trial).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.integrate import solve_bvp
from scipy.optimize import brentq


def pressure_energy(lam, E, Ri, Ro, alpha_deg, h=1e-6):
    """p(λ) = dU/dV from the strain energy and internal volume (Eqs. 2.1–2.6)."""
    a = math.radians(alpha_deg)
    c2, s2 = math.cos(a) ** 2, math.sin(a) ** 2
    at = math.pi * (Ro**2 - Ri**2)

    def energy_volume(l1):
        l2sq = (1.0 - l1**2 * c2) / s2          # Eq. 2.3 (incompressibility via the braid)
        l3 = 1.0 / (l1 * math.sqrt(l2sq))       # Eq. 2.4
        i1 = l1**2 + l2sq + l3**2               # Eq. 2.1
        u = E / 6.0 * (i1 - 3.0) * at           # Eqs. 2.2, 2.5, 2.6 per unit length
        v = math.pi * Ri**2 * l1 * l2sq         # Eq. 2.5 per unit length
        return u, v

    u1, v1 = energy_volume(lam + h)
    u0, v0 = energy_volume(lam - h)
    return (u1 - u0) / (v1 - v0)


def pressure_eq210_printed(lam, E, Ri, Ro, alpha_deg):
    """Eq. (2.10) exactly as printed in the thesis (with its sign)."""
    a = math.radians(alpha_deg)
    c, c2a = math.cos(a), math.cos(2 * a)
    num = (lam**8 * c**4 * c2a - 2 * lam**6 * c**2 * c2a + lam**4 * c2a + 2 * lam**2 * c**2 * c2a
           - c2a - 2 * lam**2 * c**6 + c**4)
    at = math.pi * (Ro**2 - Ri**2)
    area = math.pi * Ri**2
    den = 3 * lam**3 * (1 - 5 * lam**2 * c**2 + 7 * lam**4 * c**4 - 3 * lam**6 * c**6) * area
    return E * num * at / den


def stretch_bisect(p, E, Ri, Ro, alpha_deg):
    """λ at pressure p by bracketing :func:`pressure_energy` on [1, λmax)."""
    if p == 0:
        return 1.0
    lam_max = 1.0 / (math.sqrt(3.0) * math.cos(math.radians(alpha_deg)))
    return brentq(lambda lam: pressure_energy(lam, E, Ri, Ro, alpha_deg) - p, 1.0 + 1e-9,
                  lam_max - 1e-9, xtol=1e-15, rtol=1e-15)


def rest_strains(arm, channel_pressures):
    """(u1*, u2*, v3*) per section by plain loops (docs/design.md §1–4)."""
    ns = len(arm.sections)
    force = [0.0] * ns
    m1 = [0.0] * ns
    m2 = [0.0] * ns
    for tube in arm.tubes:
        mat = tube.material
        lam = stretch_bisect(channel_pressures[tube.channel], mat.youngs_modulus, mat.inner_radius,
                             mat.outer_radius, mat.wind_angle_deg)
        f = mat.youngs_modulus * mat.area * (lam - 1.0)
        a = math.radians(tube.angle_deg)
        for i in range(tube.first_section, tube.last_section + 1):
            force[i] += f
            m1[i] += f * tube.radius * math.sin(a)
            m2[i] -= f * tube.radius * math.cos(a)
    secs = arm.sections
    return (np.array([m1[i] / secs[i].EI for i in range(ns)]),
            np.array([m2[i] / secs[i].EI for i in range(ns)]),
            np.array([1.0 + force[i] / secs[i].EA for i in range(ns)]))


def solve_bvp_planar(arm, channel_pressures, scene, unshearable=False, tol=1e-10, nodes=41,
                     guess=None):
    """Planar equilibrium by scipy ``solve_bvp``; returns (tip (2,), tip angle, solution).

    Each section i is mapped to τ ∈ [0, 1]; its state is (x, y, θ, n_x, n_y, m) and
    d/dτ = L_i · d/ds with
        x' = v3 cos θ − v1 sin θ,  y' = v3 sin θ + v1 cos θ,  θ' = u*_i + m/EI_i,
        n' = −μ_i g,  m' = −(x' n_y − y' n_x).
    """
    u1, u2, v3r = rest_strains(arm, channel_pressures)
    secs = arm.sections
    ns = len(secs)
    g = np.array([0.0, -scene.gravity])
    theta0 = math.radians(scene.base_angle_deg - 90.0)
    tip_force = np.array(scene.tip_force[:2]) + scene.payload_kg * g
    m_tip = float(scene.tip_moment) if isinstance(scene.tip_moment, float) else scene.tip_moment[2]

    def rhs(tau, state):
        out = np.empty_like(state)
        for i, sec in enumerate(secs):
            x, y, th, nx, ny, m = state[6 * i: 6 * i + 6]
            c, s = np.cos(th), np.sin(th)
            n1 = -nx * s + ny * c
            n3 = nx * c + ny * s
            v1 = 0.0 if unshearable else n1 / sec.GA
            v3 = v3r[i] + n3 / sec.EA
            dx = v3 * c - v1 * s
            dy = v3 * s + v1 * c
            q = sec.mass_per_length * g
            out[6 * i: 6 * i + 6] = sec.length * np.array([
                dx, dy, u2[i] + m / sec.EI, -q[0] + 0 * x, -q[1] + 0 * y, -(dx * ny - dy * nx)])
        return out

    def bc(ya, yb):
        res = [ya[0], ya[1], ya[2] - theta0]
        for i in range(ns - 1):
            plate = secs[i].endplate_mass * g
            a, b = yb[6 * i: 6 * i + 6], ya[6 * (i + 1): 6 * (i + 1) + 6]
            res += [b[0] - a[0], b[1] - a[1], b[2] - a[2],
                    a[3] - b[3] - plate[0], a[4] - b[4] - plate[1], b[5] - a[5]]
        last = yb[6 * (ns - 1): 6 * ns]
        plate = secs[-1].endplate_mass * g
        res += [last[3] - tip_force[0] - plate[0], last[4] - tip_force[1] - plate[1],
                last[5] - m_tip]
        return np.array(res)

    tau = np.linspace(0.0, 1.0, nodes)
    if guess is None:
        guess = np.zeros((6 * ns, nodes))
        start = 0.0
        for i, sec in enumerate(secs):
            guess[6 * i + 0] = np.cos(theta0) * (start + sec.length * tau)
            guess[6 * i + 1] = np.sin(theta0) * (start + sec.length * tau)
            guess[6 * i + 2] = theta0
            start += sec.length
    sol = solve_bvp(rhs, bc, tau, guess, tol=tol, max_nodes=200000)
    if not sol.success:
        raise RuntimeError(f"solve_bvp failed: {sol.message}")
    end = sol.sol(1.0)[6 * (ns - 1): 6 * ns]
    return end[:2], end[2], sol


def nearest_stable_root_full_scan(residual, stable, m_bound, n_scan, guess):
    """The stable root of ``residual`` (a function of the base moment) nearest ``guess``, from
    every sign change of an ``n_scan``-interval grid over [−m_bound, m_bound], each root by
    ``scipy.optimize.brentq``; ``stable(m)`` says whether a root is stable. Ties (distances
    within 1e-12·m_bound) go to the larger root. Returns (root or NaN, every stable root)."""
    grid = [-m_bound + 2.0 * m_bound * k / n_scan for k in range(n_scan + 1)]
    r = [residual(m) for m in grid]
    roots = []
    for k in range(1, n_scan + 1):
        if math.isfinite(r[k]) and math.isfinite(r[k - 1]) and (r[k] == 0.0 or r[k - 1] * r[k] < 0.0):
            root = grid[k] if r[k] == 0.0 else brentq(residual, grid[k - 1], grid[k],
                                                     xtol=1e-14 * m_bound, rtol=1e-15)
            if stable(root):
                roots.append(root)
    if not roots:
        return math.nan, roots
    nearest = min(abs(m - guess) for m in roots)
    return max(m for m in roots if abs(m - guess) <= nearest + 1e-12 * m_bound), roots


def march_planar(residual, m_start, n_steps=400, max_move=None):
    """The quasi-static branch from the root ``m_start`` of ``residual(0, ·)`` to t = 1, by
    ``n_steps`` equal steps of t, each a plain Newton solve from the linear extrapolation of
    the last two roots. ``residual(t, m0)`` returns (r, ∂r/∂m0, stable). Returns the root at
    t = 1, or None where the march cannot vouch for one branch: Newton fails, a root is
    unstable, or a step moves the root by more than ``max_move`` (default: unbounded)."""
    roots = [m_start, m_start]
    for k in range(1, n_steps + 1):
        t = k / n_steps
        m = 2.0 * roots[-1] - roots[-2]
        for _ in range(50):
            r, dr, stable = residual(t, m)
            if not math.isfinite(r) or dr == 0.0:
                return None
            m -= r / dr
            if abs(r) < 1e-11:
                break
        else:
            return None
        r, dr, stable = residual(t, m)
        if not stable or (max_move is not None and abs(m - roots[-1]) > max_move):
            return None
        roots.append(m)
    return roots[-1]


def march_spatial(residual, m_start, n_steps=400, max_move=None):
    """:func:`march_planar` for a spatial base moment (3,): ``residual(t, m0)`` returns (r (3,),
    ∂r/∂m0 (3, 3), stable); plain Newton steps solved by numpy."""
    roots = [np.asarray(m_start, dtype=float)] * 2
    for k in range(1, n_steps + 1):
        t = k / n_steps
        m = 2.0 * roots[-1] - roots[-2]
        for _ in range(50):
            r, jac, stable = residual(t, m)
            if not np.all(np.isfinite(r)) or not np.all(np.isfinite(jac)):
                return None
            m = m - np.linalg.solve(jac, r)
            if np.linalg.norm(r) < 1e-11:
                break
        else:
            return None
        r, jac, stable = residual(t, m)
        if not stable or (max_move is not None and np.linalg.norm(m - roots[-1]) > max_move):
            return None
        roots.append(m)
    return roots[-1]


def rest_gradient_forward(arm, eq, rest):
    """∂m0/∂u*_i and ∂m0/∂v*_i of a recorded planar equilibrium, m(L) held: the linearised
    statics δθ' = δm/EI + δu*, δm' = K·δθ − n1·δv* integrated forward by Heun's rule on the
    recorded nodes, once for each section's u* and v* and once for m0.

    Args:
        arm: the design. eq: a recorded planar Equilibrium of it. rest: (3, ns) its rest
            strains (u1*, u2*, v3*).

    Returns:
        (2, ns): rows ∂m0/∂u* (N m²), ∂m0/∂v* (N m).
    """
    ns = len(arm.sections)
    ends = np.asarray(eq.section_ends)
    starts = np.concatenate([[0], ends[:-1] + 1])

    def stiffness_and_shear(row, sec, vr):
        th = eq.angles[row]
        nx, ny = eq.internal_force[row]
        n1 = -nx * math.sin(th) + ny * math.cos(th)
        n3 = nx * math.cos(th) + ny * math.sin(th)
        return (1 / sec.GA - 1 / sec.EA) * (n1 * n1 - n3 * n3) + vr * n3, n1

    def response(par):
        a, b = 0.0, 1.0 if par == 2 * ns else 0.0
        for i, sec in enumerate(arm.sections):
            du = 1.0 if par == 2 * i else 0.0
            dv = 1.0 if par == 2 * i + 1 else 0.0
            for r in range(starts[i], ends[i]):
                h = eq.s[r + 1] - eq.s[r]
                k0, n1_0 = stiffness_and_shear(r, sec, rest[2][i])
                k1, n1_1 = stiffness_and_shear(r + 1, sec, rest[2][i])
                da0, db0 = b / sec.EI + du, k0 * a - dv * n1_0
                a_pred, b_pred = a + h * da0, b + h * db0
                da1, db1 = b_pred / sec.EI + du, k1 * a_pred - dv * n1_1
                a, b = a + 0.5 * h * (da0 + da1), b + 0.5 * h * (db0 + db1)
        return b

    db_dm0 = response(2 * ns)
    return np.array([[-response(2 * i + k) / db_dm0 for i in range(ns)] for k in range(2)])


def rk4_planar(arm, rest, scene, m0, steps=2000):
    """Plain-Python RK4 of the solver's own planar ODE from base moment m0 (no Newton).

    ``rest`` = (u1*, u2*, v3*) per section, so that the integrator alone is compared.
    """
    u1, u2, v3r = rest
    g = np.array([0.0, -scene.gravity])
    secs = arm.sections
    # n just proximal of each section end, from the tip inwards.
    running = np.array(scene.tip_force[:2]) + scene.payload_kg * g
    n_end = [None] * len(secs)
    for i in range(len(secs) - 1, -1, -1):
        running = running + secs[i].endplate_mass * g
        n_end[i] = running.copy()
        running = running + secs[i].mass_per_length * g * secs[i].length
    state = np.array([0.0, 0.0, math.radians(scene.base_angle_deg - 90.0), m0])
    for i, sec in enumerate(secs):
        def f(sig, st, i=i, sec=sec):
            x, y, th, m = st
            n = n_end[i] + sec.mass_per_length * g * (sec.length - sig)
            c, s = math.cos(th), math.sin(th)
            n1 = -n[0] * s + n[1] * c
            n3 = n[0] * c + n[1] * s
            v1, v3 = n1 / sec.GA, v3r[i] + n3 / sec.EA
            return np.array([v3 * c - v1 * s, v3 * s + v1 * c, u2[i] + m / sec.EI,
                             v1 * n3 - v3 * n1])
        h = sec.length / steps
        for j in range(steps):
            sig = j * h
            k1 = f(sig, state)
            k2 = f(sig + h / 2, state + h / 2 * k1)
            k3 = f(sig + h / 2, state + h / 2 * k2)
            k4 = f(sig + h, state + h * k3)
            state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return state


def elastica_cantilever(alpha):
    """Inextensible cantilever, horizontal clamp, dead vertical tip load, α = P L²/EI.

    From EI φ'' = −P cos φ with φ(0) = 0, φ'(L) = 0 (φ the downward slope):
    φ' = √(2P/EI)·√(sin ψ − sin φ), so √α = (1/√2)∫₀^ψ dφ/√(sin ψ − sin φ),
    u/L = 1 − √(2 sin ψ/α) and w/L = (1/√(2α))∫₀^ψ sin φ dφ/√(sin ψ − sin φ).
    The end singularity is removed by φ = ψ − v². Returns (w/L, u/L, ψ) to ~1e-12.
    """
    import warnings

    from scipy.integrate import IntegrationWarning, quad

    def integral(psi, weight):
        def f(v):
            phi = psi - v * v
            # sin ψ − sin φ = 2 cos((ψ+φ)/2) sin(v²/2), written so that it keeps its digits.
            half = 0.5 * v * v
            if half == 0.0:
                return 2.0 * weight(psi) / math.sqrt(math.cos(psi))
            gap = 2.0 * math.cos(psi - half) * math.sin(half)
            return 2.0 * v * weight(phi) / math.sqrt(gap)
        with warnings.catch_warnings():
            # quad's round-off notice fires near 1e-12; the result matches the printed table
            # to all its digits and our solver to ~1e-11.
            warnings.simplefilter("ignore", IntegrationWarning)
            return quad(f, 0.0, math.sqrt(psi), epsabs=1e-12, epsrel=1e-11, limit=200)[0]

    psi = brentq(lambda p: integral(p, lambda _: 1.0) / math.sqrt(2.0) - math.sqrt(alpha),
                 1e-6, math.pi / 2 - 1e-9, xtol=1e-15)
    w = integral(psi, math.sin) / math.sqrt(2.0 * alpha)
    u = 1.0 - math.sqrt(2.0 * math.sin(psi) / alpha)
    return w, u, psi


def moment_balance(arm, scene, eq):
    """The planar moment balance of every recorded sample of ``eq``, from its positions and
    tangents and the scene's loads only (no shooting, no integration of the rod equations):

        m(s_k) = M_tip + (r(L) − r_k) × F + Σ_{endplates distal} (r_j − r_k) × W_j
                 + ∫_{s_k}^L (r(σ) − r_k) × q dσ,

    F the tip force plus payload weight, W_j the endplate weights, q each section's weight per
    length; ∫ r dσ by the trapezoid rule with the end correction h²/12·(r'_a − r'_b) (cubic
    Hermite, O(h⁵) per step), r' = v3 d3 + v1 d1 from the recorded angles and strains.

    Returns:
        (N,) m_recorded − m_balance (N m).
    """
    g = np.array([0.0, -scene.gravity])
    force = np.asarray(scene.tip_force[:2]) + scene.payload_kg * g
    r, th = eq.positions, eq.angles
    v1, v3 = eq.shear_stretch[:, 0], eq.shear_stretch[:, 1]
    tangent = np.column_stack([v3 * np.cos(th) - v1 * np.sin(th), v3 * np.sin(th) + v1 * np.cos(th)])

    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    n = eq.s.size
    moment_q = np.zeros(n)  # ∫_{s_k}^L r × q dσ
    weight_q = np.zeros((n, 2))  # ∫_{s_k}^L q dσ
    start = 0
    sections = []
    for section, end in zip(arm.sections, eq.section_ends):
        sections.append((start, end, section.mass_per_length * g))
        start = end + 1
    acc_m, acc_w = 0.0, np.zeros(2)
    for first, end, q in reversed(sections):
        moment_q[end], weight_q[end] = acc_m, acc_w
        for k in range(end - 1, first - 1, -1):
            h = eq.s[k + 1] - eq.s[k]
            chord = 0.5 * h * (r[k] + r[k + 1]) + h * h / 12.0 * (tangent[k] - tangent[k + 1])
            acc_m, acc_w = acc_m + cross(chord, q), acc_w + q * h
            moment_q[k], weight_q[k] = acc_m, acc_w
    balance = scene.tip_moment_3d()[2] + cross(r[-1] - r, force) + moment_q - cross(r, weight_q)
    for section, end in zip(arm.sections, eq.section_ends):
        distal = np.arange(n) <= end
        balance[distal] += cross(r[end] - r[distal], section.endplate_mass * g)
    return eq.internal_moment - balance


def solve_bvp_rod_on_obstacle(rod, scene, obstacle, guess_eq, tol=1e-6, nodes=401):
    """A passive one-section rod (:func:`solver.designs.rod`, no gravity) pressed on a
    cylinder or sphere by its tip load, by scipy ``solve_bvp``; returns the tip (3,).

    The state is (r, d1, d2, d3, n, m) (18,): directors as vectors, not a quaternion, and
    the contact written from the obstacle's geometry alone:
        r' = Σ v_k d_k,  d_k' = ω × d_k,  ω = Σ u_k d_k,
        v = (n·d1/GA, n·d2/GA, 1 + n·d3/EA),  u = (m·d1/EI, m·d2/EI, m·d3/GJ),
        n' = −k·max(0, R − |e|)·e/|e|,  m' = −r' × n,
    e the offset of r from the axis (cylinder) or centre (sphere). ``guess_eq`` (a recorded
    spatial Equilibrium) only seeds the mesh: the answer is whatever satisfies the equations.
    """
    sec = rod.sections[0]
    length = sec.length
    point = np.array(obstacle.point if hasattr(obstacle, "axis") else obstacle.center)
    axis = np.array(obstacle.axis) if hasattr(obstacle, "axis") else np.zeros(3)
    k, radius = obstacle.stiffness, obstacle.radius
    theta0 = math.radians(scene.base_angle_deg - 90.0)
    base = np.array([[-math.sin(theta0), 0.0, math.cos(theta0)],
                     [math.cos(theta0), 0.0, math.sin(theta0)],
                     [0.0, 1.0, 0.0]])
    force = np.array(scene.tip_force_3d())
    moment = np.array(scene.tip_moment_3d())

    def rhs(s, y):
        r, d1, d2, d3, n, m = (y[3 * j:3 * j + 3] for j in range(6))
        v = [np.sum(n * d1, 0) / sec.GA, np.sum(n * d2, 0) / sec.GA, 1.0 + np.sum(n * d3, 0) / sec.EA]
        u = [np.sum(m * d1, 0) / sec.EI, np.sum(m * d2, 0) / sec.EI, np.sum(m * d3, 0) / sec.GJ]
        dr = v[0] * d1 + v[1] * d2 + v[2] * d3
        w = u[0] * d1 + u[1] * d2 + u[2] * d3
        e = r - point[:, None]
        e = e - np.sum(e * axis[:, None], 0) * axis[:, None]
        dist = np.linalg.norm(e, axis=0)
        f = k * np.maximum(0.0, radius - dist) * e / np.where(dist > 0, dist, 1.0)
        return np.concatenate([dr, np.cross(w, d1, axis=0), np.cross(w, d2, axis=0),
                               np.cross(w, d3, axis=0), -f, -np.cross(dr, n, axis=0)])

    def bc(ya, yb):
        return np.concatenate([ya[0:3], ya[3:6] - base[:, 0], ya[6:9] - base[:, 1],
                               ya[9:12] - base[:, 2], yb[12:15] - force, yb[15:18] - moment])

    s = np.linspace(0.0, length, nodes)
    guess = np.empty((18, nodes))
    for c in range(3):
        guess[c] = np.interp(s, guess_eq.s, guess_eq.positions[:, c])
        for j in range(3):
            guess[3 + 3 * j + c] = np.interp(s, guess_eq.s, guess_eq.orientations[:, c, j])
        guess[12 + c] = np.interp(s, guess_eq.s, guess_eq.internal_force[:, c])
        guess[15 + c] = np.interp(s, guess_eq.s, guess_eq.internal_moment[:, c])
    sol = solve_bvp(rhs, bc, s, guess, tol=tol, max_nodes=40000)
    if not sol.success:
        raise RuntimeError(f"solve_bvp failed: {sol.message}")
    return sol.sol(length)[:3]


def newton_spatial_contact_plain(Z, grid, rest, level, weights, res_weights, scales, tol,
                                 max_iter, max_step, past_kinks):
    """Damped Newton on the 3D contact system at ``level`` from the node states ``Z`` (updated
    in place), the textbook way: at each iterate a Jacobian pass (residual, Jacobian and segment
    maps by the variational equations), the step clipped to ``max_step`` (weighted RMS) and
    halved up to seven times until a residual pass finds the residual lower; where none does,
    go on from the smallest trial (``past_kinks``) or stop. The rules of
    :func:`solver.kernels.spatial_contact.newton_into`, in its order of passes before it
    formed first trials with their Jacobians.

    Returns:
        (converged, iterations, residual, F (n,), J (n, n), blocks (K, 12, 12), first trials
        accepted, first trials refused).
    """
    from solver.kernels.contact import weighted_norm
    from solver.kernels.spatial_contact import (
        N_CTANGENT,
        NO_TETHER,
        newton_system,
        retract,
        tangent_system,
    )
    from solver.kernels.spatial_shooting import banded_solve

    n = weights.shape[0]
    F, F_try, J = np.empty(n), np.empty(n), np.empty((n, n))
    blocks = np.empty((Z.shape[0], N_CTANGENT, N_CTANGENT))
    no_jacobian = np.empty((0, 0))
    taken = refused = 0
    if not tangent_system(Z, grid, rest, level, F, J, blocks):
        return False, 0, math.inf, F, J, blocks, taken, refused
    res = weighted_norm(F, res_weights)
    for it in range(max_iter + 1):
        if not math.isfinite(res):
            return False, it, math.inf, F, J, blocks, taken, refused
        if res <= tol:
            return True, it, res, F, J, blocks, taken, refused
        if it == max_iter:
            break
        step = np.empty(n)
        if not banded_solve(J.copy(), F.copy(), step):
            return False, it, res, F, J, blocks, taken, refused
        norm = weighted_norm(step, weights)
        alpha = max_step / norm if norm > max_step else 1.0
        base = Z.copy()
        first_taken = False
        for trial in range(8):
            retract(base, step, -alpha, Z)
            res_try = math.inf
            if newton_system(Z, grid, rest, level, F_try, no_jacobian, False, blocks, scales,
                             NO_TETHER):
                res_try = weighted_norm(F_try, res_weights)
                if res_try < res:
                    first_taken = trial == 0
                    break
            alpha *= 0.5
        taken += first_taken
        refused += not first_taken
        if not math.isfinite(res_try) or not (past_kinks or res_try < res):
            Z[:, :] = base
            return False, it + 1, res, F, J, blocks, taken, refused
        if not tangent_system(Z, grid, rest, level, F, J, blocks):
            return False, it + 1, math.inf, F, J, blocks, taken, refused
        res = weighted_norm(F, res_weights)
    return False, max_iter, res, F, J, blocks, taken, refused
