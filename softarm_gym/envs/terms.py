"""Batch-first action, observation and reward functions of the soft-arm environments.

One copy of each rule, shared by the single environments (:class:`SoftArmEnv`,
:class:`ReachEnv`, with a batch of one) and the batched vector environment
(:mod:`softarm_gym.vector`), so that a policy sees the same numbers from either. Every
function takes (n, ...) arrays and writes into preallocated outputs; the numba kernels cost
about a microsecond per call for one copy.

Planar backbone records are the solver's (:mod:`solver.layout`: columns ``S`` … ``U``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from solver.jit import njit, prange
from solver.layout import THETA, V1, V3, S, X, Y
from solver.rod import hermite_resample, turned

__all__ = ["fractions_from_actions", "fill_true_shapes", "fill_true_shapes_parallel", "fill_shape",
           "fill_pressures", "clip_observations", "fill_reach_goals", "goal_rewards", "reach_rewards",
           "reach_reward_sum", "reward_sums", "REACH_TERMS", "WRAP_TERMS", "WrapRule", "wrap_measures",
           "wrap_rewards", "contact_forces", "contact_rewards", "obstacle_terms", "OBSTACLE_TERMS",
           "tracking_errors", "equilibrium_contact", "batch_contact", "batch_wrap_rewards"]

REACH_TERMS = ("reward_distance", "reward_control", "reward_success", "reward_solver")
"""The reward terms of the reach task, in the column order of :func:`reach_rewards`."""

WRAP_TERMS = ("reward_wrap", "reward_approach", "reward_penetration", "reward_control",
              "reward_success", "reward_solver")
"""The reward terms of the wrap task, in the column order of :func:`wrap_rewards`."""


OBSTACLE_TERMS = ("reward_distance", "reward_control", "reward_success", "reward_contact",
                  "reward_solver")
"""The reward terms of the obstacle-reach task, in the column order of :func:`obstacle_terms`."""


class WrapRule(NamedTuple):
    """The wrap task's measures and reward weights (the arguments of
    :class:`~softarm_gym.envs.WrapEnv` of the same names; its env card's Rewards)."""

    contact_margin: float
    wrap_weight: float
    approach_weight: float
    penetration_weight: float
    penetration_tolerance: float
    control_weight: float
    success_bonus: float
    success_wrap_deg: float
    solver_failure_penalty: float


@njit
def fractions_from_actions(actions, fractions, delta, delta_scale, out):
    """Channel pressures as fractions of p_max from normalised actions in [−1, 1].

    Absolute mode: (a + 1)/2. Delta mode: the current fraction plus ``delta_scale``·a,
    clipped to [0, 1]. Actions are clipped to [−1, 1] first.

    Args:
        actions: (n, k) actions. fractions: (n, k) current fractions (delta mode).
        delta: delta mode. delta_scale: fraction of p_max per unit action.
        out: (n, k) written.

    Returns:
        −1, or the flat index of the first non-finite action (``out`` is then incomplete).
    """
    n, k = actions.shape
    for e in range(n):
        for c in range(k):
            a = actions[e, c]
            if not math.isfinite(a):
                return e * k + c
            a = min(max(a, -1.0), 1.0)
            if delta:
                out[e, c] = min(max(fractions[e, c] + delta_scale * a, 0.0), 1.0)
            else:
                out[e, c] = 0.5 * (a + 1.0)
    return -1


@njit
def fill_true_shapes(records, section_ends, s_query, starts, obs, tips, tangent, backbone):
    """The shape blocks of planar ``true`` observations from recorded backbones.

    Tip (x, y); per section end (x, y, cos θ, sin θ); the backbone resampled at ``s_query``
    by cubic Hermite with dr/ds = v3 d3 + v1 d1 (the rule of
    :func:`softarm_gym.sensing.shape_from_equilibrium`), its last sample the exact tip.

    Args:
        records: (n, N, N_COLUMNS) backbone records. section_ends: (ns,) their end rows.
        s_query: (K,) arc lengths of the backbone samples (m).
        starts: (3,) int: where the tip, section-end and backbone blocks start in ``obs``.
        obs: (n, D) observations, written in those blocks. tips: (n, 2) written.
        tangent: (n, N, 2) and backbone: (n, K, 2) scratch, one per copy.
    """
    for e in range(records.shape[0]):
        _fill_true_shape(records[e], section_ends, s_query, starts, obs[e], tips[e], tangent[e],
                         backbone[e])


@njit(parallel=True)
def fill_true_shapes_parallel(records, section_ends, s_query, starts, obs, tips, tangent, backbone):
    """:func:`fill_true_shapes` over numba's threads: the same numbers."""
    for e in prange(records.shape[0]):
        _fill_true_shape(records[e], section_ends, s_query, starts, obs[e], tips[e], tangent[e],
                         backbone[e])


@njit(inline="always")
def _fill_true_shape(rec, section_ends, s_query, starts, o, tip, tangent, backbone):
    """:func:`fill_true_shapes` of one record ``rec`` into its observation ``o`` and ``tip``."""
    rows = rec.shape[0]
    # cos θ and sin θ carried from row to row by the turn between them (rows a fraction of
    # an RK4 step apart): libm's pair at every row was most of this function's time.
    th = rec[0, THETA]
    c = math.cos(th)
    sn = math.sin(th)
    for r in range(rows):
        if r:
            c, sn = turned(th, c, sn, rec[r, THETA] - th)
            th = rec[r, THETA]
        tangent[r, 0] = rec[r, V3] * c - rec[r, V1] * sn
        tangent[r, 1] = rec[r, V3] * sn + rec[r, V1] * c
    hermite_resample(rec[:, S], rec[:, X:Y + 1], tangent, s_query, backbone)
    tip[0] = rec[rows - 1, X]
    tip[1] = rec[rows - 1, Y]
    backbone[backbone.shape[0] - 1, 0] = tip[0]
    backbone[backbone.shape[0] - 1, 1] = tip[1]
    o[starts[0]] = tip[0]
    o[starts[0] + 1] = tip[1]
    for i in range(section_ends.shape[0]):
        r = section_ends[i]
        b = starts[1] + 4 * i
        o[b] = rec[r, X]
        o[b + 1] = rec[r, Y]
        o[b + 2] = math.cos(rec[r, THETA])
        o[b + 3] = math.sin(rec[r, THETA])
    for j in range(backbone.shape[0]):
        o[starts[2] + 2 * j] = backbone[j, 0]
        o[starts[2] + 2 * j + 1] = backbone[j, 1]


def fill_shape(obs, slices, shape, planar: bool) -> None:
    """The shape blocks of one observation ``obs`` (D,) from an estimator's
    :class:`~softarm_gym.sensing.ShapeEstimate`: tip; per section end (x, y, cos θ, sin θ)
    planar or (x, y, z, d3) spatial; the backbone samples. ``slices``: the blocks' places."""
    obs[slices["tip"]] = shape.tip
    ends = obs[slices["section_ends"]].reshape(shape.section_ends.shape[0], -1)
    if planar:
        ends[:, :2] = shape.section_ends[:, :2]
        ends[:, 2] = np.cos(shape.section_ends[:, 2])
        ends[:, 3] = np.sin(shape.section_ends[:, 2])
    else:
        ends[:, :3] = shape.section_ends
        ends[:, 3:] = shape.section_frames[:, :, 2]
    obs[slices["backbone"]] = shape.backbone.ravel()


@njit
def fill_pressures(fractions, start, obs):
    """The pressures block, 2·fraction − 1 ∈ [−1, 1], of ``obs`` (n, D) from (n, k)."""
    for e in range(fractions.shape[0]):
        for c in range(fractions.shape[1]):
            obs[e, start + c] = 2.0 * fractions[e, c] - 1.0


@njit
def clip_observations(obs, low, high, out):
    """``out`` (n, D) float32 = ``obs`` (n, D) clipped to the space bounds (D,)."""
    for e in range(obs.shape[0]):
        for d in range(obs.shape[1]):
            out[e, d] = min(max(obs[e, d], low[d]), high[d])


@njit
def fill_reach_goals(targets, tips, start, obs):
    """The reach goal block of ``obs`` (n, D) from ``start``: the target (dim) and the
    target relative to the observed tip (dim), from ``targets`` and ``tips`` (n, dim) (m)."""
    dim = targets.shape[1]
    for e in range(targets.shape[0]):
        for c in range(dim):
            obs[e, start + c] = targets[e, c]
            obs[e, start + dim + c] = targets[e, c] - tips[e, c]


@njit(inline="always")
def _control_term(fraction, control_weight):
    """``reward_control`` of one copy: −w_c·mean(fraction²) of its (k,) pressure fractions."""
    effort = 0.0
    for c in range(fraction.shape[0]):
        effort += fraction[c] * fraction[c]
    return -control_weight * effort / fraction.shape[0]


@njit
def goal_rewards(tips, targets, distance_weight, success_bonus, success_tolerance, terms, distance,
                 success):
    """The goal-dependent reach terms: −w_d·|tip − target| and the bonus on success.

    Args:
        tips, targets: (n, dim) (m): the achieved and desired goals.
        terms: (n, 4) columns 0 (``reward_distance``) and 2 (``reward_success``) written.
        distance: (n,) written (m). success: (n,) written: distance <= ``success_tolerance``.
    """
    for e in range(tips.shape[0]):
        d2 = 0.0
        for c in range(tips.shape[1]):
            d2 += (tips[e, c] - targets[e, c]) ** 2
        dist = math.sqrt(d2)
        distance[e] = dist
        success[e] = dist <= success_tolerance
        terms[e, 0] = -distance_weight * dist
        terms[e, 2] = success_bonus if success[e] else 0.0


@njit
def reach_rewards(tips, targets, fractions, converged, distance_weight, control_weight,
                  success_bonus, success_tolerance, failure_penalty, terms, distance, success):
    """Reach rewards: −w_d·|tip − target| − w_c·mean(fraction²) + bonus on success − the
    solver-failure penalty on an unconverged step (the goal terms by :func:`goal_rewards`).

    Args:
        tips, targets: (n, dim) (m). fractions: (n, k) pressures / p_max. converged: (n,).
        terms: (n, 4) written, columns :data:`REACH_TERMS`. distance: (n,) written (m).
        success: (n,) written: distance <= ``success_tolerance``.
    """
    goal_rewards(tips, targets, distance_weight, success_bonus, success_tolerance, terms, distance,
                 success)
    for e in range(tips.shape[0]):
        terms[e, 1] = _control_term(fractions[e], control_weight)
        terms[e, 3] = 0.0 if converged[e] else -failure_penalty


def reach_reward_sum(terms: np.ndarray) -> np.ndarray:
    """Rewards (n,) from the (n, 4) terms, summed in the column order (:func:`reward_sums`)."""
    out = np.empty(terms.shape[0])
    reward_sums(terms, out)
    return out


@njit
def reward_sums(terms, out):
    """``out`` (n,) = the rewards of the (n, k) ``terms``: 0 plus each term in the column
    order, as a single env sums its ``reward_*`` terms."""
    for e in range(terms.shape[0]):
        total = 0.0
        for j in range(terms.shape[1]):
            total += terms[e, j]
        out[e] = total


@njit
def wrap_measures(positions, centers, contact_radii, margin, wrap, gap):
    """The wrap angle and gap of backbones about discs.

    A sample within ``contact_radii + margin`` of its disc's centre is in contact; the polar
    angles of those samples about the centre, in arc-length order and unwrapped (the rule of
    ``numpy.unwrap``: a jump of at least π between consecutive ones is taken the short way
    round), span the wrap angle, max − min (a spiral passing a point twice counts beyond 2π;
    0 with fewer than two contact samples). The gap is the smallest distance from a sample to
    the contact circle, 0 when touching.

    Args:
        positions: (n, N, 2) backbone samples, base to tip (m); any strides (e.g. the ``X``,
            ``Y`` columns of backbone records).
        centers: (n, 2) disc centres (m). contact_radii: (n,) contact radii (m).
        margin: gap still counted as contact (m).
        wrap: (n,) written (rad). gap: (n,) written (m).
    """
    for e in range(positions.shape[0]):
        wrap[e], gap[e] = _wrap_measure(positions[e], centers[e, 0], centers[e, 1], contact_radii[e],
                                        margin)


@njit(inline="always")
def _wrap_measure(positions, cx, cy, contact_radius, margin):
    """(wrap angle (rad), gap (m)) of one backbone ``positions`` (N, 2) about the disc at
    (cx, cy): :func:`wrap_measures`."""
    limit = contact_radius + margin
    closest = math.inf
    count = 0
    previous = 0.0
    correction = 0.0
    low = math.inf
    high = -math.inf
    for r in range(positions.shape[0]):
        dx = positions[r, 0] - cx
        dy = positions[r, 1] - cy
        distance = math.hypot(dx, dy)
        closest = min(closest, distance)
        if distance <= limit:
            phi = math.atan2(dy, dx)
            if count:
                jump = phi - previous
                if abs(jump) >= math.pi:
                    turned_back = (jump + math.pi) % (2.0 * math.pi) - math.pi
                    if turned_back == -math.pi and jump > 0.0:
                        turned_back = math.pi
                    correction += turned_back - jump
            previous = phi
            unwrapped = phi + correction
            low = min(low, unwrapped)
            high = max(high, unwrapped)
            count += 1
    return (high - low if count >= 2 else 0.0), max(closest - contact_radius, 0.0)


@njit
def wrap_rewards(positions, centers, contact_radii, penetration, fractions, converged, rule, terms,
                 wrap_deg, gap, success):
    """Wrap rewards (the env card's Rewards of :class:`~softarm_gym.envs.WrapEnv`):
    w_wrap·min(wrap, 2π)/2π − w_approach·gap − w_pen·penetration/tolerance − w_c·mean(fraction²)
    + bonus on success − the solver-failure penalty on an unconverged step, the wrap angle and
    gap by :func:`wrap_measures`. Success: wrap >= ``success_wrap_deg`` with penetration <=
    ``penetration_tolerance``.

    Args:
        positions, centers, contact_radii: as :func:`wrap_measures`.
        penetration: (n,) deepest penetration (m). fractions: (n, k) pressures / p_max.
        converged: (n,) bool. rule: the :class:`WrapRule`.
        terms: (n, 6) written, columns :data:`WRAP_TERMS`. wrap_deg: (n,) written (deg).
        gap: (n,) written (m). success: (n,) written.
    """
    for e in range(positions.shape[0]):
        wrap, gap[e] = _wrap_measure(positions[e], centers[e, 0], centers[e, 1], contact_radii[e],
                                     rule.contact_margin)
        degrees = math.degrees(wrap)
        wrap_deg[e] = degrees
        success[e] = degrees >= rule.success_wrap_deg and penetration[e] <= rule.penetration_tolerance
        terms[e, 0] = rule.wrap_weight * min(wrap, 2.0 * math.pi) / (2.0 * math.pi)
        terms[e, 1] = -rule.approach_weight * gap[e]
        terms[e, 2] = -rule.penetration_weight * penetration[e] / rule.penetration_tolerance
        terms[e, 3] = _control_term(fractions[e], rule.control_weight)
        terms[e, 4] = rule.success_bonus if success[e] else 0.0
        terms[e, 5] = 0.0 if converged[e] else -rule.solver_failure_penalty


@njit
def contact_forces(s, forces, out):
    """Total contact force ∫ |f| ds (N) of penalty force densities ``forces`` (n, N, 2) (N/m)
    at arc lengths ``s`` (n, N) (m), by the trapezoidal rule in arc-length order (the
    solver's rule for :meth:`solver.Stepper.contact_measures`); ``out`` (n,) written."""
    for e in range(forces.shape[0]):
        previous = math.hypot(forces[e, 0, 0], forces[e, 0, 1])
        total = 0.0
        for r in range(1, forces.shape[1]):
            f = math.hypot(forces[e, r, 0], forces[e, r, 1])
            total += 0.5 * (f + previous) * (s[e, r] - s[e, r - 1])
            previous = f
        out[e] = total


@njit
def contact_rewards(forces, touching, forbid, contact_weight, contact_penalty, out):
    """``reward_contact`` of the states steps reached (before a forbidden contact is
    rejected): with ``forbid``, −``contact_penalty`` where the state touches an obstacle,
    else 0; otherwise −``contact_weight``·F.

    Args:
        forces: (n,) total contact forces F (N). touching: (n,) bool. out: (n,) written.
    """
    for e in range(forces.shape[0]):
        if forbid:
            out[e] = -contact_penalty if touching[e] else 0.0
        else:
            out[e] = -contact_weight * forces[e]


@njit
def obstacle_terms(reach_terms, contact, out):
    """The obstacle-reach terms (n, 5), columns :data:`OBSTACLE_TERMS`, from the reach terms
    (n, 4) of :func:`reach_rewards` and ``reward_contact`` (n,) of :func:`contact_rewards`."""
    for e in range(reach_terms.shape[0]):
        out[e, 0] = reach_terms[e, 0]
        out[e, 1] = reach_terms[e, 1]
        out[e, 2] = reach_terms[e, 2]
        out[e, 3] = contact[e]
        out[e, 4] = reach_terms[e, 3]


@njit
def tracking_errors(distance, steps, squares, largest, rms):
    """Running tracking statistics after a step: ``squares`` (n,) += distance², ``largest``
    (n,) = max(largest, distance), ``rms`` (n,) = sqrt(squares / steps) — the RMS and the
    largest of the distances (m) of an episode's ``steps`` (n,) steps so far."""
    for e in range(distance.shape[0]):
        squares[e] += distance[e] * distance[e]
        largest[e] = max(largest[e], distance[e])
        rms[e] = math.sqrt(squares[e] / steps[e])


# ------------------------------------------------------------------ batched states


def equilibrium_contact(eq) -> tuple[float, float]:
    """A :class:`solver.Equilibrium`'s deepest penetration (m) and total contact force ∫|f| ds
    (N, :func:`contact_forces`); zeros without contact."""
    if not eq.in_contact or not eq.contact_force.size:
        return (float(eq.penetration.max()) if eq.penetration.size else 0.0), 0.0
    out = np.empty(1)
    contact_forces(eq.s[None], eq.contact_force[None], out)
    return float(eq.penetration.max()), float(out[0])


def batch_contact(batch, measures: np.ndarray) -> np.ndarray:
    """Which copies of a contact :class:`solver.BatchStepper` hold a lean record, and every
    copy's deepest penetration and total contact force into ``measures`` (n, 2): from the
    batch's records, or for a copy without one (a state the general path left on a grid of
    its own), from its equilibrium — as a single env reads its stepper. Returns the (n,) bool
    mask of :meth:`solver.BatchStepper.recorded`."""
    recorded = batch.recorded()
    measures[:] = batch.contact_measures()
    for k in np.flatnonzero(~recorded):
        measures[k] = equilibrium_contact(batch.equilibrium(k))
    return recorded


def batch_wrap_rewards(batch, backbones, recorded, centers, contact_radii, penetration, fractions,
                       converged, rule, terms, wrap_deg, gap, success) -> None:
    """:func:`wrap_rewards` of every copy of a contact :class:`solver.BatchStepper`: from its
    backbones (n, N, N_COLUMNS), or for a copy not ``recorded``, from its equilibrium's
    backbone (as a single env without a record)."""
    wrap_rewards(backbones[:, :, X:Y + 1], centers, contact_radii, penetration, fractions, converged,
                 rule, terms, wrap_deg, gap, success)
    for k in np.flatnonzero(~recorded):
        row = slice(k, k + 1)
        wrap_rewards(batch.equilibrium(k).positions[None], centers[row], contact_radii[row],
                     penetration[row], fractions[row], converged[row], rule, terms[row], wrap_deg[row],
                     gap[row], success[row])
