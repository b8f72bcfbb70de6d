"""Classical comparisons for the RL baselines: a damped-least-squares Jacobian controller
(reach, obstacle reach, track), a scripted curl (wrap) and a sampling-based model-predictive
planner (all of them).

:class:`JacobianController` acts on exactly the observation vector a policy sees, and on
nothing else of the episode. What it knows:

* **Configuration** (as a user who built the env would): the *nominal* design
  (``env.arm``, not the randomised arm being simulated), the base angle, the rated pressure
  p_max, the action mode and ``delta_scale``, and the layout of the flat observation.
* **Each step, from the observation**: the estimated tip (the ``tip`` block, produced by the
  env's shape estimator from the synthesised, possibly noisy, sensors), the commanded
  pressures (``pressures``) and the target (first two entries of ``goal``).
* **Not**: the true tip, the payload (its nominal model assumes none), the randomised arm.

Each step it advances its own nominal equilibrium to the commanded pressures (a solve
warm-started from its previous nominal state, so it follows the quasi-static path as the
arm does), takes J = ∂tip/∂p of that nominal equilibrium by central finite differences
(:func:`softarm_gym.analysis.jacobian`, the manipulability Jacobian), scaled to pressure
fractions, J_f = J·p_max (m per unit fraction), and commands f ← f + Δf with::

    Δf = argmin |J_f Δ − gain·e|² + λ²|Δ|² + μ²|f + Δ − ½|²,   e = x_goal − x_tip_observed,
         subject to 0 ≤ f + Δ ≤ 1 and |Δ_k| ≤ max_step,

solved exactly as a bounded linear least-squares problem (``scipy.optimize.lsq_linear``,
BVLS). Without the bounds and μ this is the damped-least-squares step
Δf = J_fᵀ (J_f J_fᵀ + λ² I)⁻¹ e with λ = ``damping`` (m). The bounds replace clipping, so a
saturated channel hands its share to the redundant ones instead of the step being clipped
away. μ = ``centering``·min(1, |e|/``centering_radius``) pulls the pressures towards
mid-range while the tip is far from the goal and fades out near it (so the final error is not
biased); without it, box-constrained descent stalls in local minima with a channel pinned at
a bound (measured: 1 of 50 OctArm and 1 of 50 CT targets). When the nominal Jacobian cannot
be taken (a perturbed solve snaps: a fold of the nominal path) the last one is reused; at the
first step of an episode the controller then holds the pressures.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from scipy.optimize import lsq_linear

import solver
from softarm_gym.analysis import jacobian
from softarm_gym.envs.terms import (
    OBSTACLE_TERMS,
    WRAP_TERMS,
    batch_contact,
    batch_wrap_rewards,
    contact_rewards,
    fractions_from_actions,
    obstacle_terms,
    reach_rewards,
    reward_sums,
)
from solver.grasp import CLAMP_GAP, FreeObject, Settler

__all__ = ["JacobianController", "CurlController", "CEMPlanner", "distinct_scores", "observation_slices"]


def observation_slices(env) -> dict[str, slice]:
    """The blocks of a flat reach observation: name → slice, in flat order.

    The layout is the environment's own (``tip``, ``section_ends``, ``backbone``, ``pressures``,
    ``goal``), read from the env rather than recomputed, so it cannot drift from it.

    Args:
        env: a (possibly wrapped) soft-arm environment.
    """
    return env.unwrapped.observation_slices


class _PressureController:
    """Turns the commanded pressures of ``step_fraction`` into actions of the env's action mode.

    Subclasses set ``action_mode``, ``delta_scale`` and ``_slices`` and define ``step_fraction``.
    """

    def act(self, obs: np.ndarray) -> np.ndarray:
        """The action (env's action mode, float32 in [-1, 1]) for a flat observation."""
        obs = np.asarray(obs, dtype=float)
        target = self.step_fraction(obs)
        if self.action_mode == "absolute":
            action = 2.0 * target - 1.0
        else:
            # Delta actions increment the command (the ``commanded`` block under pneumatic lag).
            current = 0.5 * (obs[self._slices.get("commanded", self._slices["pressures"])] + 1.0)
            action = (target - current) / self.delta_scale
        return np.clip(action, -1.0, 1.0).astype(np.float32)


class JacobianController(_PressureController):
    """Box-constrained damped-least-squares control on the nominal model (module docstring).

    Args:
        env: the environment it will act in (read once for its configuration).
        damping: λ (m) of the damped least squares.
        gain: fraction of the error corrected per step, in (0, 1].
        max_step: largest pressure change per step on any channel, fraction of p_max, in (0, 1].
        centering: μ (m per unit fraction) of the pull towards mid-range pressures, in (0, 1].
        centering_radius: tip error (m) below which the pull fades linearly to zero.
        rel_step: finite-difference step of the Jacobian, fraction of p_max.

    Raises:
        ValueError: bad gains, or an environment whose observations are not flat reach vectors.
    """

    def __init__(self, env, damping: float = 0.03, gain: float = 1.0, max_step: float = 0.1,
                 centering: float = 0.05, centering_radius: float = 0.05, rel_step: float = 1e-4):
        for name, value, low, high in (("damping", damping, 0.0, np.inf), ("gain", gain, 0.0, 1.0),
                                       ("max_step", max_step, 0.0, 1.0), ("centering", centering, 0.0, 1.0),
                                       ("centering_radius", centering_radius, 0.0, np.inf)):
            if not (np.isfinite(value) and low < value <= high):
                raise ValueError(f"{name} must lie in ({low}, {high}]; got {value!r}")
        base = env.unwrapped
        if getattr(base, "observation_format", None) != "flat" or not hasattr(base, "success_tolerance"):
            raise ValueError("JacobianController needs a reach environment with observation_format='flat'")
        if not base.planar:
            raise ValueError("JacobianController is planar: make the env with planar=True")
        self.arm = base.arm
        self.scene = solver.Scene(base_angle_deg=base.base_angle_deg)
        self.p_max = float(base.p_max)
        self.action_mode = base.action_mode
        self.delta_scale = float(base.delta_scale)
        self.damping = float(damping)
        self.gain = float(gain)
        self.max_step = float(max_step)
        self.centering = float(centering)
        self.centering_radius = float(centering_radius)
        self.rel_step = float(rel_step)
        self._slices = observation_slices(env)
        self._n = base.n_inputs
        self._nominal = None
        self._jac = None

    def reset(self) -> None:
        """Forget the nominal state and Jacobian (call at every episode start)."""
        self._nominal = None
        self._jac = None

    def _track(self, fraction: np.ndarray) -> None:
        """Advance the nominal equilibrium to the commanded pressures and refresh J."""
        eq = solver.solve(self.arm, fraction * self.p_max, self.scene, planar=True,
                          warm_start=self._nominal, record=False)
        if not eq.converged:
            return
        self._nominal = eq
        try:
            self._jac = jacobian(self.arm, eq, rel_step=self.rel_step) * self.p_max
        except solver.SolverError:
            pass

    def step_fraction(self, obs: np.ndarray) -> np.ndarray:
        """The next commanded pressures (fractions of p_max) for a flat observation."""
        obs = np.asarray(obs, dtype=float)
        fraction = 0.5 * (obs[self._slices["pressures"]] + 1.0)
        tip = obs[self._slices["tip"]]
        goal = obs[self._slices["goal"]][:2]
        self._track(fraction)
        if self._jac is None:
            return fraction
        error = goal - tip
        centering = self.centering * min(1.0, float(np.hypot(*error)) / self.centering_radius)
        rows = np.vstack([self._jac, self.damping * np.eye(self._n), centering * np.eye(self._n)])
        rhs = np.concatenate([self.gain * error, np.zeros(self._n), centering * (0.5 - fraction)])
        low = np.maximum(-fraction, -self.max_step)
        high = np.minimum(1.0 - fraction, self.max_step)
        delta = lsq_linear(rows, rhs, bounds=(low, high), method="bvls").x
        return np.clip(fraction + delta, 0.0, 1.0)


_MIN_INCREMENT = 1e-3
"""CurlController's smallest pressure step (fraction of p_max), far above float32 rounding."""


class CurlController(_PressureController):
    """Scripted wrap: curl every section towards the disc, ramping to p_max, then hold.

    What it knows: the nominal design (which planar inputs turn the arm clockwise and which
    counter-clockwise: the sign of Σ u2*·L over the sections with one input at p_max,
    :func:`solver.rest_strains`), the action mode and the layout of the flat observation.
    At an episode's first step it reads from the observation the estimated backbone and the
    disc centre (first two entries of ``goal``), and takes the disc's side from the cross
    product of the backbone tangent and the direction to the centre at the backbone sample
    nearest the disc. It then drives the inputs that curl towards that side up to p_max in
    steps of 1/``ramp_steps`` of p_max, and the others to zero. When the observed pressures
    show that the env rejected the last command (an unconverged contact solve keeps the
    previous state), it holds the accepted pressures for one step and then goes on with half
    the step; once the step is below 1/1000 of p_max it holds. It uses no contact or wrap
    feedback: the reference a learned wrap policy should beat.

    On a 3D wrap env (``planar=False``) the side is a heading: the object's direction from
    the backbone sample nearest it, in the base frame's (d1, d2) plane (the nominal mounting;
    the arm starts nearly straight). Each channel's weight is how far the bend it gives alone
    at p_max (Σ (u1*, u2*)·L over the sections) points that way (the cosine, clipped at 0,
    scaled so that the largest is 1), and the commands ramp to ``level`` × weight, ``level``
    rising by the step.

    On a grasp env (:class:`~softarm_gym.envs.GraspEnv`, whose goal block also holds the
    object's seat) it reads the object's centre: once the object is ``success_lift`` above its
    seat it holds the pressures, unless the object is pressed against the arm's base clamp
    (its contact circle within ``CLAMP_GAP`` + 1 mm of the base), where it backs the curl off
    by half the last increment, and so on.

    Args:
        env: a (possibly wrapped) wrap (planar or 3D) or grasp environment with
            ``observation_format='flat'``.
        ramp_steps: steps from zero to full pressure while no command is rejected (>= 1).

    Raises:
        ValueError: a bad ``ramp_steps`` or an environment that is not a flat wrap env.
    """

    def __init__(self, env, ramp_steps: int = 10):
        if isinstance(ramp_steps, bool) or int(ramp_steps) != ramp_steps or ramp_steps < 1:
            raise ValueError(f"ramp_steps must be an integer >= 1; got {ramp_steps!r}")
        base = env.unwrapped
        if getattr(base, "observation_format", None) != "flat" or not hasattr(base, "success_wrap_deg"):
            raise ValueError("CurlController needs a wrap environment with observation_format='flat'")
        self.ramp_steps = int(ramp_steps)
        self.action_mode = base.action_mode
        self.delta_scale = float(base.delta_scale)
        self._slices = observation_slices(env)
        self.planar = bool(base.planar)
        lengths = np.array([section.length for section in base.arm.sections])
        bends = np.empty((base.n_inputs, 2))
        for k in range(base.n_inputs):
            pressures = np.zeros(base.n_inputs)
            pressures[k] = base.arm.max_pressure
            channels = solver.channel_pressures(base.arm, pressures, planar=self.planar)
            u1, u2, _ = solver.rest_strains(base.arm, channels)
            bends[k] = u1 @ lengths, u2 @ lengths
        self.turning = bends[:, 1]
        """Total rest turning (rad) about d2 of the arm with each input alone at p_max (planar:
        > 0 counter-clockwise)."""
        self.bends = bends
        """(n_inputs, 2) total rest curvature (u1*, u2*)·L of each input alone at p_max (rad)."""
        self.base_frame = solver.rod.base_rotation(math.radians(base.base_angle_deg - 90.0))
        self.success_lift = getattr(base, "success_lift", None)
        """The grasp env's lift to reach (m), or None on a wrap env."""
        self.reset()

    def reset(self) -> None:
        """Forget the side, the last command and the step size (call at every episode start)."""
        self._inputs = None
        self._command = None
        self._level = 0.0
        self._increment = 1.0 / self.ramp_steps

    def _weights(self, obs: np.ndarray) -> np.ndarray:
        """3D: each channel's weight towards the object's heading (see the class docstring)."""
        backbone = obs[self._slices["backbone"]].reshape(-1, 3)
        centre = obs[self._slices["goal"]][:3]
        k = int(np.argmin(np.linalg.norm(backbone - centre, axis=1)))
        heading = self.base_frame[:, :2].T @ (centre - backbone[k])
        # A curvature (u1, u2) turns d3 towards u2·d1 − u1·d2 (d3' = u × d3).
        towards = np.column_stack([self.bends[:, 1], -self.bends[:, 0]])
        cosine = towards @ heading / (np.linalg.norm(towards, axis=1) * np.linalg.norm(heading) + 1e-300)
        weights = np.clip(cosine, 0.0, None)
        return weights / weights.max() if weights.max() > 0 else weights

    def _side(self, obs: np.ndarray) -> float:
        """+1 when the disc lies to the left of the backbone (counter-clockwise curl), else −1."""
        backbone = obs[self._slices["backbone"]].reshape(-1, 2)
        center = obs[self._slices["goal"]][:2]
        k = int(np.argmin(np.hypot(*(backbone - center).T)))
        tangent = backbone[min(k + 1, len(backbone) - 1)] - backbone[max(k - 1, 0)]
        to_center = center - backbone[k]
        return 1.0 if tangent[0] * to_center[1] - tangent[1] * to_center[0] > 0 else -1.0

    def step_fraction(self, obs: np.ndarray) -> np.ndarray:
        """The next commanded pressures (fractions of p_max) for a flat observation."""
        obs = np.asarray(obs, dtype=float)
        current = 0.5 * (obs[self._slices["pressures"]] + 1.0)
        if self._inputs is None:
            self._inputs = (np.sign(self.turning) == self._side(obs)).astype(float) \
                if self.planar else self._weights(obs)
        # The observation is float32: a command the env took matches it to ~1e-7.
        elif np.max(np.abs(current - self._command)) > 1e-5:
            # Rejected: hold the accepted state for a step (so the env's run of consecutive
            # failures ends), then go on with half the step.
            self._increment *= 0.5
            self._command = current
            return self._command
        # Below a thousandth of p_max the next rejection could not be seen: stop and hold.
        increment = self._increment if self._increment >= _MIN_INCREMENT else 0.0
        if self.success_lift is not None:
            goal = obs[self._slices["goal"]]
            if goal[1] - goal[4] >= self.success_lift:
                if math.hypot(goal[0], goal[1]) > goal[2] + _CLAMP_MARGIN:
                    self._command = current
                    return self._command
                self._increment *= 0.5  # pressed against the base clamp: curl back
                increment = -self._increment if self._increment >= _MIN_INCREMENT else 0.0
        if not self.planar:
            self._level = min(self._level + increment, 1.0)
            self._command = self._level * self._inputs
            return self._command
        step = np.where(self._inputs > 0, increment, -abs(increment))
        self._command = np.clip(current + step, 0.0, 1.0)
        return self._command


_CLAMP_MARGIN = CLAMP_GAP + 1e-3
"""CurlController on grasp: an object whose contact circle is this close to the arm's base
(m) is pressed against the base clamp (:data:`solver.grasp.CLAMP_GAP`, plus 1 mm of slack)."""

_MAX_CORNERS = 64
"""CEMPlanner tries every corner of the action box by default up to this many (6 inputs)."""


def _section_corners(arm) -> np.ndarray:
    """Bang-bang spatial actions (m, n_channels) that bend every section from the ``j``-th on
    the same way: each nonzero on/off pattern of a section's channels, applied to sections
    j … last, the others off — the corners of a spatial arm's 2^n_channels that curl it
    towards one of its channels' headings (the planar arm's corners, all of which are
    enumerated, include them)."""
    sections = np.array([next(t.first_section for t in arm.tubes if t.channel == c)
                         for c in range(arm.n_channels)])
    width = max(np.count_nonzero(sections == i) for i in range(len(arm.sections)))
    rows = []
    for pattern in range(1, 2 ** width):
        for first in range(len(arm.sections)):
            row = -np.ones(arm.n_channels)
            for i in range(first, len(arm.sections)):
                channels = np.flatnonzero(sections == i)
                on = (pattern >> np.arange(channels.size)) & 1
                row[channels] = 2.0 * on - 1.0
            rows.append(row)
    return np.unique(np.array(rows), axis=0)


def distinct_scores(score, candidates: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """``score(candidates, fraction)`` with each distinct sequence rolled out once: (m,) scores
    of the (m, horizon, n) action sequences (``score`` takes the distinct ones in the order
    they first appear, with ``fraction``, and returns theirs).

    Actions are clipped to [−1, 1] before they act, so sequences equal after clipping reach
    the same states and score the same — and they repeat: random corners of the pressure box,
    the mean's sign among them, clipped draws piled up on the box's faces (a quarter of a wrap
    search's general-path solves were repeats). The rows of a rollout are independent, so the
    scores are those of rolling out every candidate, bit for bit."""
    flat = np.clip(candidates, -1.0, 1.0).reshape(candidates.shape[0], -1)
    _, first, inverse = np.unique(flat, axis=0, return_index=True, return_inverse=True)
    if first.size == candidates.shape[0]:
        return score(candidates, fraction)
    # The distinct sequences in the order they first appear (the rows they had), each
    # candidate given its sequence's score.
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return score(candidates[first[order]], fraction)[rank[inverse.ravel()]]


def _corner_bits(n: int) -> np.ndarray:
    """(2^n, n) every corner of the unit cube [0, 1]^n (rows: the binary digits of 0 .. 2^n − 1)."""
    return ((np.arange(2 ** n)[:, None] >> np.arange(n)) & 1).astype(float)


class CEMPlanner(_PressureController):
    """Sampling-based model-predictive control: the cross-entropy method over action sequences,
    each candidate rolled out on the nominal model from the current state. Reach, obstacle
    reach, track, wrap, grasp.

    What it knows, as :class:`JacobianController`: the nominal design, the base angle, whether
    the arm presses on itself (``self_contact``, with its stiffness), p_max, the action mode
    and ``delta_scale``, the observation layout, and the task's reward rule
    with the env's weights (reach: :func:`softarm_gym.envs.terms.reach_rewards`; wrap:
    :meth:`~softarm_gym.envs.WrapEnv.wrap_terms`, the disc read from the observation and the
    env's contact stiffness; obstacle reach: the reach rule plus
    :meth:`~softarm_gym.envs.ObstacleReachEnv.contact_reward`, the discs read from the
    ``obstacles`` block, a touching step rejected as the env rejects it under
    ``contact="forbid"``; grasp: :meth:`~softarm_gym.envs.GraspEnv.grasp_terms`, the object's
    seat, centre and contact radius read from the observation, its mass taken as the middle
    of the env's ``object_mass_kg`` range, the grasp margin left out of the score). Not the
    true state, the payload, the object's mass or a randomised arm.

    Each decision (:meth:`step_fraction`):

    1. Its nominal equilibrium follows the quasi-static path to the commanded pressures read
       from the observation (the arm's own hysteresis and snaps included).
    2. ``iterations`` rounds of the cross-entropy method: ``samples`` sequences of
       ``horizon`` actions in [−1, 1] drawn from a clipped Gaussian (mean: the last plan
       shifted by one step; standard deviation ``init_std``, then the elites'), turned into
       pressures by the env's own action rule
       (:func:`~softarm_gym.envs.terms.fractions_from_actions`), stepped from the nominal state
       and scored by the sum of the task's rewards (an unconverged rollout step costs the env's
       solver-failure penalty). Holding the current pressures is always one candidate, so on
       the model the plan is never worse than standing still; the mean rounded to the box's
       corner and corners of the box are candidates too (every action at ±1: pressure limits
       make bang-bang commands optimal often, and Gaussian draws rarely hit them). With
       ``all_corners`` the first round adds every one of the 2^n_inputs corners, each held
       over the horizon, in place of its quarter of the samples drawn at random among them;
       later rounds draw a quarter at random. The ``elites`` best set the next mean and
       standard deviation.
    3. The first command of the best sequence seen is sent; the rest seeds the next decision
       (with ``commit``, the rest is sent step by step without searching, stopping where the
       nominal state succeeds).
    4. With ``escape``, where the best is holding: the best straight pressure ramp of
       ceil(1/delta_scale) steps, scored where it ends (:meth:`_search_ramps`), is followed
       as a committed sequence if it ends better than holding.

    Where the nominal state already succeeds (reach: the tip within half the success
    tolerance of the target; wrap: the success rule), it holds without searching, and so it
    does when the observation is the one from which its last search found nothing better
    than holding. Rollouts
    run on :class:`solver.BatchStepper`, all candidates of a round in one parallel call, each
    a row adopted from the nominal state and scored by the env's batch-first reward rules
    (:mod:`softarm_gym.envs.terms`): for reach and track, and for planar wrap and obstacle
    reach with the batch's lean contact step in the scene with the discs (the nominal start,
    like the envs', solved cold without the discs and then in their scene); where the scene
    has no lean contact step (3D wrap, rigid contact) one :class:`solver.Stepper` steps the
    candidates in turn; for grasp each rollout step is
    :func:`solver.grasp.settle` of arm and free object together, on at most
    ``grasp_solves`` contact solves (a snap that would cost more counts as unconverged).
    Its randomness comes from its own generator
    (``seed``), so it is reproducible.

    Args:
        env: a (possibly wrapped) planar reach, obstacle-reach, track, wrap or grasp env with
            ``observation_format='flat'`` (on track it aims where the target's last
            displacement takes it).
        samples: candidate sequences per round (>= 2; the first round has 2^n_inputs − samples/4
            more with ``all_corners``). elites: best kept per round (>= 1, < samples).
            iterations: CEM rounds per decision (>= 1). horizon: steps per sequence (>= 1;
            None: 1, except on wrap with delta actions: ceil(1/delta_scale), the steps a ramp
            across the pressure range takes, so that a held corner is a ramp to a bang-bang
            command and a snap it crosses lies within the horizon).
            init_std: first-round standard deviation (action units, > 0).
        all_corners: enumerate every corner of the action box in the first round. None
            (default): with absolute actions, where corners are the bang-bang pressure
            commands, and on wrap with delta actions, where a corner held over the horizon
            ramps to one; at most 64 corners (6 inputs). Elsewhere with delta actions a corner
            is only the largest increment. Why: the best wrap on ``SoftArm/OctArmWrap-v1`` is the full
            curl, one corner among 64; random corner draws missed it on 10 of 100 seeds, the
            search then settled on an S-curl that wraps ~95° and stopped searching there
            (docs/environments.md, "Wrap calibration").
        seed: seed of the planner's generator.
        grasp_solves: contact solves a grasp rollout step may spend (>= 1).
        commit: follow the best sequence of a search to its end (while the env takes each
            command and the task is not yet solved) before searching again. None (default):
            on wrap with delta actions, where each search rolls out every ramp (a search per
            step would cost the horizon's length again at every step); the model is the
            env's nominal arm, so the sequence plays out as planned unless the arm differs.

        escape: where a search finds nothing better than holding, search once more over
            straight pressure ramps of ceil(1/delta_scale) steps (:meth:`_search_ramps`) and
            follow the best to its end if it beats holding. None (default): on reach and
            obstacle reach with delta actions. Why: on ``SoftArm/OctArmObstacleReach-v1`` the
            one-step search stopped behind a disc 18–35 cm from the target on 3 of 20 seeds,
            though the ramp the target was drawn by reaches it (docs/environments.md,
            "Obstacle-reach calibration").

    Attributes:
        last_searched: whether the last decision ran rollouts (False: it held).
    """

    def __init__(self, env, samples: int = 32, elites: int = 6, iterations: int = 3,
                 horizon: int | None = None, init_std: float = 0.5, all_corners: bool | None = None,
                 seed: int = 0, grasp_solves: int = 60, commit: bool | None = None,
                 escape: bool | None = None):
        base = env.unwrapped
        # Rate-limited wrap: a snap is crossed by a ramp of ceil(1/delta_scale) steps, not one.
        ramps = hasattr(base, "success_wrap_deg") and getattr(base, "action_mode", None) == "delta"
        if horizon is None:
            horizon = math.ceil(1.0 / base.delta_scale - 1e-9) if ramps else 1
        if commit is None:
            commit = ramps
        elif not isinstance(commit, bool):
            raise ValueError(f"commit must be True, False or None; got {commit!r}")
        for name, value, low in (("samples", samples, 2), ("elites", elites, 1),
                                 ("iterations", iterations, 1), ("horizon", horizon, 1),
                                 ("grasp_solves", grasp_solves, 1)):
            if isinstance(value, bool) or int(value) != value or value < low:
                raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
        if elites >= samples:
            raise ValueError(f"elites ({elites}) must be fewer than samples ({samples})")
        if not (np.isfinite(init_std) and init_std > 0):
            raise ValueError(f"init_std must be > 0 (action units); got {init_std!r}")
        self.commit = commit
        if escape is None:
            escape = (base.action_mode == "delta" and hasattr(base, "success_tolerance")
                      and not hasattr(base, "success_wrap_deg") and not hasattr(base, "segment_steps")
                      and not hasattr(base, "success_lift"))
        elif not isinstance(escape, bool):
            raise ValueError(f"escape must be True, False or None; got {escape!r}")
        self.escape = escape
        self.wrap = hasattr(base, "success_wrap_deg")
        self.grasp = hasattr(base, "success_lift")
        self.grasp_solves = int(grasp_solves)
        if getattr(base, "observation_format", None) != "flat" or not (
                getattr(base, "planar", False) or self.wrap):
            raise ValueError("CEMPlanner needs a planar env (or a wrap env, planar or 3D) with "
                             "observation_format='flat'")
        self.planar = bool(base.planar)
        self.obstacles = hasattr(base, "contact_reward")
        self.contact = self.wrap or self.obstacles
        self.tracking = hasattr(base, "segment_steps")
        if not self.wrap and not hasattr(base, "success_tolerance"):
            raise ValueError("CEMPlanner plans reach and wrap tasks only")
        self.task = base  # the reward rule and its weights (configuration, not state)
        self.arm = base.arm
        # The env's physics, self-contact included (configuration: a wrap rollout without it
        # passes the tip through the arm's base where the env's arm lands on itself).
        self.scene = solver.Scene(base_angle_deg=base.base_angle_deg, gravity=base.gravity,
                                  self_contact=base.self_contact,
                                  self_friction=base.self_friction)
        self.p_max = float(base.p_max)
        self.action_mode = base.action_mode
        self.delta_scale = float(base.delta_scale)
        self.samples, self.elites, self.iterations = int(samples), int(elites), int(iterations)
        self.horizon, self.init_std, self.seed = int(horizon), float(init_std), seed
        self._slices = observation_slices(env)
        self._n = base.n_inputs
        if all_corners is None:
            all_corners = (self.action_mode == "absolute" or ramps) and 2 ** self._n <= _MAX_CORNERS
        elif not isinstance(all_corners, bool):
            raise ValueError(f"all_corners must be True, False or None; got {all_corners!r}")
        # Every corner of the action box (rows: the binary digits of 0 .. 2^n - 1), or for a
        # spatial arm with too many, the section-wise ones; each held over the horizon.
        corners = None
        if all_corners:
            corners = 2.0 * _corner_bits(self._n) - 1.0
        elif not self.planar and self.action_mode == "absolute":
            corners = _section_corners(self.arm)
        self._corners = None if corners is None else np.repeat(corners[:, None], self.horizon,
                                                                axis=1)
        # A round's candidates: hold, the rounded mean, a quarter of the samples at corners (or
        # every corner in the first round), the rest drawn: one batch row each.
        self._rows = self.samples if corners is None else \
            max(self.samples, self.samples - self.samples // 4 + corners.shape[0])
        self._batch = None if self.contact else solver.BatchStepper(self.arm, self.scene, self._rows)
        self.rng = np.random.default_rng(seed)
        self.reset()

    def reset(self) -> None:
        """Forget the nominal state, the disc and the plan (call at every episode start)."""
        self._nominal = None
        self._rollout = None
        self._settler = None
        self._plan = np.zeros((self.horizon, self._n))
        self._stalled = None
        self._pending = None  # with ``commit``: the rest of the sequence being followed
        self._expected = None  # and the pressures its last command set
        self.last_searched = False

    # ------------------------------------------------------------------ model

    def _track(self, obs: np.ndarray, fraction: np.ndarray) -> None:
        """Move the nominal equilibrium to the commanded pressures (cold at the first step)."""
        if self.grasp:
            self._track_grasp(obs, fraction)
            return
        if self._nominal is None:
            scene = self.scene
            if self.wrap:
                goal = obs[self._slices["goal"]]
                scene = replace(scene, obstacles=(self.task.object_of_goal(goal),))
                self._goal = goal.copy()
            elif self.obstacles:
                # The obstacles block: (x, y, contact radius) per slot, radius 0 for no disc.
                slots = obs[self._slices["obstacles"]].reshape(-1, 3)
                scene = replace(scene, obstacles=tuple(self._disc(d) for d in slots if d[2] > 0))
            self._nominal = solver.Stepper(self.arm, scene, planar=self.planar)
            # As the envs start: cold without the discs, then into the scene. A cold solve in the
            # scene loads the straight arm through the discs, which can catch it as it droops.
            free = solver.solve(self.arm, fraction * self.p_max, self.scene, planar=self.planar) \
                if scene.obstacles else None
            self._nominal.reset(fraction * self.p_max, warm_start=free)
            if self.contact and self.planar and self._nominal.lean_contact:
                # Every candidate a row of one contact batch in the episode's scene (BatchStepper
                # is planar; a 3D Stepper's lean contact path is SpatialContactRows).
                self._batch = solver.BatchStepper(self.arm, scene, self._rows,
                                                  max_obstacles=len(scene.obstacles))
                self._measures = np.zeros((self._rows, 2))  # penetration, contact force per row
            elif self.contact:
                # 3D or rigid contact (no batched contact step): one stepper steps them in turn.
                self._batch = None
                self._rollout = solver.Stepper(self.arm, scene, planar=self.planar)
        elif np.any(self._nominal.pressures != fraction * self.p_max):
            self._nominal.step(fraction * self.p_max)
        if not self.wrap:
            goal = obs[self._slices["goal"]]
            # A tracking target moves first within a step: aim where its last displacement
            # (the goal block's third part) takes it.
            self._goal = goal[:2] + (goal[4:6] if self.tracking else 0.0)

    def _track_grasp(self, obs: np.ndarray, fraction: np.ndarray) -> None:
        """As :meth:`_track` for grasp: the nominal state is a :class:`solver.grasp.Grasp`, arm
        and object settled together (the first, as the env places the object: on its seat, from
        the arm solved cold without it)."""
        pressures = fraction * self.p_max
        if self._nominal is None:
            goal = obs[self._slices["goal"]]
            task = self.task
            obj = FreeObject(radius=float(goal[2]), mass_kg=float(np.mean(task.object_mass_range)),
                             seat=(float(goal[3]), float(goal[4])), stiffness=task.contact_stiffness,
                             fork_depth=task.fork_depth, friction=task.friction)
            self._settler = Settler(self.arm, self.scene, obj)
            free = solver.solve(self.arm, pressures, self.scene, planar=True)
            self._nominal = self._settler.settle(pressures, center=goal[:2], warm_start=free)
        elif np.any(self._nominal.arm.pressures != pressures):
            moved = self._settler.settle(pressures, center=self._nominal.center,
                                         warm_start=self._nominal.arm)
            if moved.converged:
                self._nominal = moved

    def _score_grasp(self, actions: np.ndarray, fraction: np.ndarray) -> np.ndarray:
        """Summed grasp rewards of (m, horizon, n) action sequences, each step settling arm and
        object together from the last (an unconverged step keeps the state, as in the env).

        Sequences that agree up to a step (clipped samples pile up on the action box's faces)
        share its settle: ``settle`` is a function of its inputs, so a step is settled once
        per state and command (a third of a first grasp decision's time went on repeats)."""
        new = np.empty((1, self._n))
        totals = np.zeros(actions.shape[0])
        penalty = self.task.solver_failure_penalty
        settled = {}  # (id of the state stepped from, command bytes) → (state, its settle)
        for j, sequence in enumerate(actions):
            state, current = self._nominal, fraction.copy()
            for action in sequence:
                fractions_from_actions(action[None], current[None], self.action_mode == "delta",
                                       self.delta_scale, new)
                key = (id(state), new[0].tobytes())
                if key not in settled:
                    # The state is kept with its settle, so that its id is not reused.
                    settled[key] = state, self._settler.settle(
                        new[0] * self.p_max, center=state.center, warm_start=state.arm,
                        max_solves=self.grasp_solves)
                moved = settled[key][1]
                if moved.converged:
                    state, current = moved, new[0].copy()
                terms = self.task.grasp_terms(state, self._settler.obj, current)[0]
                totals[j] += sum(terms.values()) + (0.0 if moved.converged else -penalty)
        return totals

    def _wrap_object(self) -> tuple:
        """(centre, contact radius, axis) of the wrap goal block, as ``wrap_terms`` takes them."""
        goal = self._goal
        return (goal[:2], float(goal[2]), None) if self.planar else \
            (goal[:3], float(goal[6]), goal[3:6])

    def _disc(self, row: np.ndarray) -> solver.Disc:
        """The disc of an observation's (x, y, contact radius) with the env's contact stiffness."""
        return solver.Disc(center=(float(row[0]), float(row[1])), radius=float(row[2]),
                           stiffness=self.task.contact_stiffness)

    def _score_batch(self, actions: np.ndarray, fraction: np.ndarray, final: bool = False) -> np.ndarray:
        """Summed task rewards of (m, horizon, n) action sequences (``final``: the last step's
        reward alone), one row of the batched model
        each (m <= the batch's rows; the others idle), every row from the nominal state. An
        unconverged step keeps its row's state, a step that touches under
        ``contact="forbid"`` is rejected, as the env does; rewards by the env's rules
        (:mod:`softarm_gym.envs.terms`)."""
        batch, task = self._batch, self.task
        n, m = batch.n, actions.shape[0]
        active = np.arange(n) < m
        padded = np.zeros((n, *actions.shape[1:]))
        padded[:m] = actions
        batch.adopt(self._nominal.equilibrium)
        fractions = np.repeat(fraction[None], n, axis=0)
        new = np.empty_like(fractions)
        total, reward = np.zeros(n), np.empty(n)
        forbid = self.obstacles and task.contact == "forbid"
        rejected = np.zeros(n, dtype=bool)
        for h in range(actions.shape[1]):
            fractions_from_actions(padded[:, h], fractions, self.action_mode == "delta",
                                   self.delta_scale, new)
            previous = [batch.equilibrium(k) for k in range(m)] if forbid else None
            report = batch.step(new * self.p_max, active=active)
            accepted = report.converged.copy()
            if self.contact:
                self._recorded = batch_contact(batch, self._measures)
                if forbid:
                    rejected = accepted & active & (self._measures[:, 0] > 0.0)
                    for k in np.flatnonzero(rejected):
                        batch.adopt(previous[k], rows=[k])
                    if rejected.any():
                        self._recorded = batch_contact(batch, self._measures)
                    accepted &= ~rejected
            fractions = np.where(accepted[:, None], new, fractions)
            self._step_rewards(report.converged, fractions, rejected, reward)
            total = reward.copy() if final else total + reward
        return total[:m]

    def _step_rewards(self, converged, fractions, rejected, out) -> None:
        """The task's rewards ``out`` (batch rows,) of the batch's states after a step, by the
        env's rules; ``rejected``: steps a forbidden contact turned back."""
        batch, task = self._batch, self.task
        n = batch.n
        if self.wrap:
            terms = np.empty((n, len(WRAP_TERMS)))
            centre, radius, _ = self._wrap_object()
            batch_wrap_rewards(batch, batch.backbones(), self._recorded, np.repeat(centre[None], n, axis=0),
                               np.full(n, radius), self._measures[:, 0], fractions, converged,
                               task.wrap_rule, terms, np.empty(n), np.empty(n), np.empty(n, dtype=bool))
            reward_sums(terms, out)
            return
        terms, distance = np.empty((n, 4)), np.empty(n)
        reach_rewards(batch.tips, np.repeat(self._goal[None], n, axis=0), fractions, converged,
                      task.distance_weight, task.control_weight, task.success_bonus,
                      task.success_tolerance, task.solver_failure_penalty, terms, distance,
                      np.empty(n, dtype=bool))
        if not self.obstacles:
            reward_sums(terms, out)
            return
        contact, all_terms = np.empty(n), np.empty((n, len(OBSTACLE_TERMS)))
        contact_rewards(self._measures[:, 1], rejected | (self._measures[:, 0] > 0.0),
                        task.contact == "forbid", task.contact_weight, task.contact_penalty, contact)
        obstacle_terms(terms, contact, all_terms)
        reward_sums(all_terms, out)

    def _score_stepper(self, actions: np.ndarray, fraction: np.ndarray, final: bool = False) -> np.ndarray:
        """:meth:`_score_batch` in a contact scene the batch does not take (3D wrap, rigid
        contact): the sequences rolled out one by one on a :class:`solver.Stepper`, scored by
        the env's per-equilibrium rules (``wrap_terms``, ``contact_reward``)."""
        rollout, start = self._rollout, self._nominal.equilibrium
        new = np.empty((1, self._n))
        totals = np.zeros(actions.shape[0])
        forbid = self.obstacles and self.task.contact == "forbid"
        for j, sequence in enumerate(actions):
            rollout.adopt(start)
            current = fraction.copy()
            for action in sequence:
                fractions_from_actions(action[None], current[None], self.action_mode == "delta",
                                       self.delta_scale, new)
                previous = rollout.equilibrium
                report = rollout.step(new[0] * self.p_max)
                contact = 0.0
                if report.converged:
                    reached = rollout.equilibrium
                    if self.obstacles:
                        contact = self.task.contact_reward(reached)[0]
                    if forbid and reached.in_contact:
                        rollout.adopt(previous)
                    else:
                        current = new[0].copy()
                reward = self._wrap_reward if self.wrap else self._reach_reward
                step = contact + reward(rollout.equilibrium, current, report.converged)
                totals[j] = step if final else totals[j] + step
        return totals

    def _reach_reward(self, eq: solver.Equilibrium, fraction: np.ndarray, converged: bool) -> float:
        terms, distance = np.empty((1, 4)), np.empty(1)
        task = self.task
        reach_rewards(eq.tip[None], self._goal[None], fraction[None], np.array([converged]),
                      task.distance_weight, task.control_weight, task.success_bonus,
                      task.success_tolerance, task.solver_failure_penalty, terms, distance,
                      np.empty(1, dtype=bool))
        reward = np.empty(1)
        reward_sums(terms, reward)
        return float(reward[0])

    def _wrap_reward(self, eq: solver.Equilibrium, fraction: np.ndarray, converged: bool) -> float:
        penetration = float(eq.penetration.max()) if eq.penetration.size else 0.0
        terms, _, _ = self.task.wrap_terms(eq.positions, penetration, fraction,
                                           *self._wrap_object())
        return sum(terms.values()) + (0.0 if converged else -self.task.solver_failure_penalty)

    def _succeeds(self, fraction: np.ndarray) -> bool:
        if self.grasp:
            return self.task.grasp_terms(self._nominal, self._settler.obj, fraction)[1]
        eq = self._nominal.equilibrium
        if self.wrap:
            penetration = float(eq.penetration.max()) if eq.penetration.size else 0.0
            return self.task.wrap_terms(eq.positions, penetration, fraction,
                                        *self._wrap_object())[1]
        return float(np.hypot(*(eq.tip - self._goal))) <= 0.5 * self.task.success_tolerance

    # ------------------------------------------------------------------ control

    def _hold(self, fraction: np.ndarray) -> np.ndarray:
        """Actions (horizon, n) that keep the pressures at ``fraction``."""
        if self.action_mode == "delta":
            return np.zeros((self.horizon, self._n))
        return np.repeat((2.0 * fraction - 1.0)[None], self.horizon, axis=0)

    def step_fraction(self, obs: np.ndarray) -> np.ndarray:
        """The next commanded pressures (fractions of p_max) for a flat observation."""
        obs = np.asarray(obs, dtype=float)
        fraction = 0.5 * (obs[self._slices["pressures"]] + 1.0)
        self._track(obs, fraction)
        self.last_searched = False
        if self._succeeds(fraction):
            self._pending = None
            return fraction
        if self._pending is not None and len(self._pending) \
                and np.max(np.abs(fraction - self._expected)) <= 1e-5:  # float32 observation
            # Following the committed sequence: the env took its last command.
            return self._command_of(self._pending[:1], fraction)
        self._pending = None
        score = self._score_grasp if self.grasp else self._score_batch if self._batch is not None \
            else self._score_stepper
        hold = self._hold(fraction)
        mean = np.vstack([self._plan[1:], self._plan[-1:]]) if self._plan.any() else hold
        std = np.full_like(mean, self.init_std)
        best, best_score = hold, -np.inf
        if self._stalled is not None and np.array_equal(self._stalled, obs):
            return fraction  # nothing better was found from this very state: do not search again
        self.last_searched = True
        for i in range(self.iterations):
            n_corners = self.samples // 4
            noise = self.rng.standard_normal((self.samples - 2 - n_corners, *mean.shape))
            draws = np.clip(mean + std * noise, -1, 1)
            # Pressure limits make bang-bang commands (every channel at 0 or p_max) optimal
            # often, and Gaussian draws rarely hit them: the mean rounded to the box's corner
            # and corners are candidates too, every one of them in the first round if so
            # configured (a single good corner among 2^n is missed by a few random draws).
            if i == 0 and self._corners is not None:
                corners = self._corners
            else:
                corners = self.rng.choice([-1.0, 1.0], size=(n_corners, *mean.shape))
            candidates = np.concatenate([hold[None], np.sign(mean)[None], corners, draws])
            scores = distinct_scores(score, candidates, fraction)
            order = np.argsort(-scores, kind="stable")
            if scores[order[0]] > best_score:
                best, best_score = candidates[order[0]], scores[order[0]]
            elite = candidates[order[:self.elites]]
            mean, std = elite.mean(axis=0), elite.std(axis=0) + 0.02
        self._plan = best
        self._stalled = obs.copy() if np.array_equal(best, hold) else None
        if self.commit and self._stalled is None:
            self._pending = best
        elif self._stalled is not None and self.escape:
            ramp = self._search_ramps(fraction, score)
            if ramp is not None:
                self._stalled, self._pending = None, ramp
        return self._command_of(best[:1] if self._pending is None else self._pending[:1], fraction)

    def _ramps(self, fraction: np.ndarray, goals: np.ndarray) -> np.ndarray:
        """Delta actions (m, ceil(1/delta_scale), n) of the straight ramps from ``fraction`` to
        each of the (m, n) pressure ``goals`` (fractions of p_max) in the fewest equal steps an
        action can take, then holding there."""
        length = math.ceil(1.0 / self.delta_scale - 1e-9)
        span = goals - fraction[None]
        steps = np.maximum(1, np.ceil(np.max(np.abs(span), axis=1) / self.delta_scale - 1e-9))
        actions = np.zeros((goals.shape[0], length, self._n))
        for j, (k, row) in enumerate(zip(steps.astype(int), span)):
            actions[j, :k] = row / (k * self.delta_scale)
        return np.clip(actions, -1.0, 1.0)

    def _search_ramps(self, fraction: np.ndarray, score) -> np.ndarray | None:
        """Where a search found nothing better than holding: the cross-entropy method over the
        pressures a straight ramp from ``fraction`` ends at (:meth:`_ramps`), each ramp scored
        by the task's reward where it ends (the last of ceil(1/delta_scale) steps), against
        holding. The best ramp's actions if it ends better than holding, else None.

        Why: a tip behind a disc, with the target beyond it, has every single rate-limited step
        farther from the target (or pressing on the disc) than holding, and sequences of
        independent draws rarely make the coherent detour; a ramp to other pressures is the
        detour a rate-limited arm makes, the way the obstacle reach's targets are drawn. Scored
        where it ends, not summed along the way: a detour first moves away from the target."""
        rows = self._batch.n if self._batch is not None else self.samples

        def scored(candidates):
            return distinct_scores(lambda distinct, start: np.concatenate(
                [score(distinct[i:i + rows], start, final=True) for i in range(0, len(distinct), rows)]),
                candidates, fraction)

        corners = _corner_bits(self._n) if 2 ** self._n <= _MAX_CORNERS else \
            self.rng.integers(0, 2, (self.samples, self._n)).astype(float)
        hold = self._ramps(fraction, fraction[None])
        goals = np.vstack([corners, self.rng.uniform(0.0, 1.0, (self.samples, self._n))])
        best, best_score = None, float(scored(hold)[0])
        for _ in range(self.iterations):
            candidates = self._ramps(fraction, goals)
            scores = scored(candidates)
            order = np.argsort(-scores, kind="stable")
            if scores[order[0]] > best_score:
                best, best_score = candidates[order[0]], float(scores[order[0]])
            elite = goals[order[:self.elites]]
            mean, std = elite.mean(axis=0), elite.std(axis=0) + 0.02
            goals = np.clip(mean + std * self.rng.standard_normal((self.samples, self._n)), 0.0, 1.0)
        return best

    def _command_of(self, action: np.ndarray, fraction: np.ndarray) -> np.ndarray:
        """The pressures (fractions of p_max) the (1, n) ``action`` commands from ``fraction``;
        with ``commit``, the sequence being followed moves on by that action."""
        target = np.empty((1, self._n))
        fractions_from_actions(action, fraction[None], self.action_mode == "delta", self.delta_scale,
                               target)
        if self._pending is not None:
            self._pending = self._pending[1:]
            self._expected = target[0].copy()
        return target[0]
