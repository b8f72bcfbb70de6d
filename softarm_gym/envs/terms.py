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

import numpy as np

from solver.jit import njit, prange
from solver.layout import THETA, V1, V3, S, X, Y
from solver.rod import hermite_resample, turned

__all__ = ["fractions_from_actions", "fill_true_shapes", "fill_true_shapes_parallel", "fill_shape",
           "fill_pressures", "clip_observations", "fill_reach_goals", "goal_rewards", "reach_rewards",
           "reach_reward_sum", "REACH_TERMS"]

REACH_TERMS = ("reward_distance", "reward_control", "reward_success", "reward_solver")
"""The reward terms of the reach task, in the column order of :func:`reach_rewards`."""


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
        effort = 0.0
        for c in range(fractions.shape[1]):
            effort += fractions[e, c] * fractions[e, c]
        terms[e, 1] = -control_weight * effort / fractions.shape[1]
        terms[e, 3] = 0.0 if converged[e] else -failure_penalty


def reach_reward_sum(terms: np.ndarray) -> np.ndarray:
    """Rewards (n,) from the (n, 4) terms, summed in the column order."""
    return terms[:, 0] + terms[:, 1] + terms[:, 2] + terms[:, 3]
