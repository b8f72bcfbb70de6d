"""Reach among obstacles: bring the tip to a target past rigid discs
(``SoftArm/OctArmObstacleReach-v0``, ``SoftArm/CTObstacleReach-v0``)."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

import solver
from softarm_gym.envs.config import check_options, finite_number, value_range
from softarm_gym.envs.reach import ReachEnv
from softarm_gym.envs.terms import contact_rewards, equilibrium_contact
from softarm_gym.envs.wrap import arm_half_thickness, check_contact_stiffness, resolve_contact_stiffness
from solver.scene import check_friction

__all__ = ["ObstacleReachEnv", "CONTACT_MODES", "total_contact_force"]

CONTACT_MODES = ("penalize", "forbid")
"""What touching an obstacle does: costs reward in proportion to the contact force, or is
rejected (the step keeps the previous state and costs ``contact_penalty``)."""

TASK_ATTEMPTS = 200
"""Draws of target and discs tried before reset gives up (each a cold solve and placements:
milliseconds; the CT arm, short and with targets near its start, needs tens at times)."""

DISC_ATTEMPTS = 30
"""Random placements tried per disc before the episode's target is redrawn."""

PLACEMENT_SPAN = (0.2, 0.8)
"""Where along the segment from the start tip to the target a disc centre is drawn
(fractions of its length)."""


def total_contact_force(eq: solver.Equilibrium) -> float:
    """The total contact force on the arm (N): ∫ |f(s)| ds of the penalty force per reference
    length over the backbone (trapezoidal rule on the solver's samples,
    :func:`softarm_gym.envs.terms.contact_forces`); 0 without contact."""
    return equilibrium_contact(eq)[1]


def _count_range(value) -> tuple[int, int]:
    """``n_obstacles`` as an inclusive (low, high) integer range with 1 <= low <= high."""
    pair = value if isinstance(value, (tuple, list)) else (value, value)
    ok = len(pair) == 2 and all(not isinstance(v, bool) and isinstance(v, (int, np.integer)) for v in pair)
    if not ok or not 1 <= pair[0] <= pair[1]:
        raise ValueError(f"n_obstacles must be an integer >= 1 or a (low, high) pair of them with "
                         f"low <= high; got {value!r}")
    return int(pair[0]), int(pair[1])


class ObstacleReachEnv(ReachEnv):
    """Reach a target past rigid discs with the tip of a soft arm (planar, quasi-static, contact).

    ## Description

    The reach task of :class:`~softarm_gym.envs.reach.ReachEnv` (same designs, mounting,
    sensing, estimators, action and stepping) with one or more rigid discs between the arm's
    start tip and the target. Contact is the solver's penalty contact (``solver.Disc``, as in
    :class:`~softarm_gym.envs.wrap.WrapEnv`): the backbone is pushed out of a disc of contact
    radius ``obstacle radius + h`` (h the distal section's half-thickness,
    :func:`~softarm_gym.envs.wrap.arm_half_thickness`) with ``contact_stiffness`` N/m² per
    metre of penetration. A soft arm may lean on an obstacle (``contact="penalize"``: the
    contact force costs reward) or must not touch one (``contact="forbid"``: a step whose
    equilibrium touches a disc is rejected).

    ## Action Space

    As ReachEnv: ``Box(-1, 1, (n_inputs,), float32)`` normalised channel pressures,
    p = (a + 1)/2 · p_max (``absolute``) or increments of ``delta_scale`` · p_max (``delta``);
    p_max OctArm V 100 psi, OctArm VI 90 psi, CT 70 psi. Out-of-range values are clipped; NaN or
    inf raises ``ValueError`` naming the channel.

    ## Observation Space

    The ReachEnv blocks ``tip`` (2, m), ``section_ends`` (4·n_sections: x, y, cos θ, sin θ),
    ``backbone`` (2·n_backbone, m), ``pressures`` (n_inputs, 2p/p_max − 1) (and
    ``commanded`` under ``actuation="lag"``), then ``obstacles`` (3·max_obstacles): per disc
    its centre (x, y) and contact radius obstacle radius + h (m), one slot per possible disc
    (``max_obstacles`` = the upper end of ``n_obstacles``), unused slots all zero (radius 0:
    no disc), then ``goal`` (4): the target (x, y) and target − estimated tip (m). Flat
    ``Box`` or ``Dict`` in this order (``observation_format``); ``"goal"`` is refused
    (``ValueError``): the contact term is not part of the goal-conditioned reward.

    ## Rewards

    ``reward = reward_distance + reward_control + reward_success + reward_contact +
    reward_solver`` (each in ``info``): the ReachEnv terms (true tip; ``success_tolerance``
    2 cm) and ``reward_contact``: with ``contact="penalize"``, −``contact_weight`` · F, F the
    total contact force on the arm (N, :func:`total_contact_force`: ∫ |f| ds of the penalty
    force per length over the backbone, from the equilibrium); with ``contact="forbid"``,
    −``contact_penalty`` on a rejected step, else 0 (an accepted state never touches).

    ## Starting State

    Per episode: the simulated arm, payload and start pressures as ReachEnv; then target and
    discs together: (1) target pressures uniform in [0, p_max], solved cold without discs;
    (2) ``n`` discs (n uniform in ``n_obstacles``, drawn once per reset), each with an
    obstacle radius uniform in ``obstacle_radius``, its centre uniform along the middle of the
    segment from the start tip to the target (fractions :data:`PLACEMENT_SPAN` of its length)
    and offset across it by up to its contact radius, so it stands in the tip's straight way
    to the target; a disc is kept only if its contact circle is at least ``clearance`` from
    the base, the target, the start backbone, the target pressures' backbone (without discs)
    and the other discs (:data:`DISC_ATTEMPTS` tries per disc); (3) the start state
    re-solved in the scene with the discs; (4) the start pressures ramped straight to the target
    pressures *in the scene with the discs, from the start state*, in the fewest equal steps
    an action can take (one with ``action_mode="absolute"``; steps of at most
    ``delta_scale``·p_max with ``"delta"``), each the quasi-static path of an env step,
    contact included, which may catch on a disc: the target is the last tip, kept only if
    every step converges and the tip is ``clearance`` clear of every disc — and, with
    ``contact="forbid"``, only if no step's equilibrium touches a disc. So the actions of
    that ramp reach every target from the start, in either contact mode (with
    ``"penalize"`` possibly leaning on a disc). With ``"forbid"`` a disc in the direct way
    would make the ramp touch, so there the discs also keep ``clearance`` from the ramp's
    backbones without discs and may stand up to half the start-tip–target distance further
    aside: they block other ways to the target, not the ramp. A failure at any stage
    redraws target and discs (:data:`TASK_ATTEMPTS` times; if none fits, the same again with
    one disc fewer, down to the lower end of ``n_obstacles``; then ``RuntimeError``).
    ``options={"obstacles": [(x, y, radius), ...]}`` fixes the discs (obstacle radii, m; at
    most ``max_obstacles``) and ``options={"target": (x, y)}`` the target (checked as in
    ReachEnv); with a fixed target the discs are placed as above without the target-backbone
    clearance (its pressures are unknown), and ``target_pressures_pa`` is None.

    ## Episode End

    Truncated at ``max_episode_steps`` (registered default 100) or after
    ``max_solver_failures`` consecutive unconverged steps. Terminated on success only with
    ``terminate_on_success=True``. A rejected step (``contact="forbid"``) does not end the
    episode.

    ## Arguments

    All ReachEnv arguments (``planar`` True only: contact is planar; ``observation_format``
    ``"flat"`` or ``"dict"``; the registered IDs set ``action_mode="delta"``,
    ``delta_scale=0.1``: absolute jumps drive the arm through the discs, and a step that snaps
    off one costs the solver seconds), plus: ``n_obstacles`` ((1, 2): an integer or an inclusive
    ``(low, high)`` range), ``obstacle_radius`` ((0.03, 0.06) m: a number or a range; the
    contact radius adds h = 30.2 mm for OctArm V and CT), ``clearance`` (0.02 m),
    ``contact`` (``"penalize"`` or ``"forbid"``, which also changes the placement: Starting
    State), ``contact_weight`` (0.1 per N),
    ``contact_penalty`` (1), ``contact_stiffness`` (``"tube"``: the distal tubes' ring
    stiffness, as WrapEnv; a number in N/m²; or ``"rigid"``), ``friction`` (the discs'
    Coulomb coefficient μ ≥ 0, 0: frictionless; docs/design.md §9). ReachEnv's
    ``self_friction`` (0) is the Coulomb coefficient between parts of the arm in
    self-contact (with ``self_contact``; docs/design.md §9.1): ``friction`` does not set it.

    ## Info

    ReachEnv's keys (``tip_true``, ``tip_estimated``, ``estimation_error``, ``sensors``,
    ``converged``, ``solver``, ``solver_failures``, ``pressures_pa``, ``payload_kg``,
    ``target``, ``distance``, ``is_success``), plus ``n_obstacles`` (n), ``obstacles``
    ((max_obstacles, 3): centre x, y and obstacle radius, m, rows after the n-th zero, as in the
    observation, so vector envs can stack them), ``contact_radii`` ((max_obstacles,), m, zero
    after the n-th), ``contact_force`` (N, total, of the current state — of the rejected
    attempt on a rejected step), ``penetration`` (m, deepest, current state),
    ``in_contact``, ``contact_rejected`` and the ``reward_*`` terms.

    ## Vector Environments

    ``gym.make_vec(id, N, vectorization_mode="vector_entry_point")`` gives
    :class:`softarm_gym.vector.BatchedObstacleReachVectorEnv`: N arms stepped by one contact
    :class:`solver.BatchStepper` call, each with its episode's discs, copy i bit for bit this
    env seeded s + i (resets by one ObstacleReachEnv per copy; ``contact="forbid"`` keeps each
    copy's equilibrium before a step, which costs about as much as the step). It refuses
    ``contact_stiffness="rigid"`` and what the batched envs refuse (docs/environments.md,
    "Batched environment").

    ## Version History

    * v0: initial version (registered with delta actions). Kept; ``gym.make`` notes that v1
      exists.
    * v1 (recommended): ``self_contact=True`` (the arm presses on itself instead of passing
      through), otherwise v0 (delta actions, 10 % of p_max per step; docs/environments.md,
      "Sequential and self-contacting versions").
    """

    def __init__(self, design="octarm_v", *, n_obstacles=(1, 2), obstacle_radius=(0.03, 0.06),
                 clearance: float = 0.02, contact: str = "penalize", contact_weight: float = 0.1,
                 contact_penalty: float = 1.0, contact_stiffness="tube", friction: float = 0.0,
                 **kwargs):
        self.n_obstacles_range = _count_range(n_obstacles)
        self.max_obstacles = self.n_obstacles_range[1]
        self.obstacle_radius_range = value_range("obstacle_radius", obstacle_radius)
        if self.obstacle_radius_range[0] <= 0:
            raise ValueError(f"obstacle_radius must be > 0 (m); got {obstacle_radius!r}")
        self.clearance = finite_number("clearance", clearance, 0.0)
        if contact not in CONTACT_MODES:
            raise ValueError(f"unknown contact {contact!r}; choose one of {', '.join(CONTACT_MODES)}")
        self.contact = contact
        self.contact_weight = finite_number("contact_weight", contact_weight, 0.0)
        self.contact_penalty = finite_number("contact_penalty", contact_penalty, 0.0)
        check_contact_stiffness(contact_stiffness)
        self.friction = check_friction("friction", friction)
        if kwargs.get("planar", True) is not True:
            raise ValueError("ObstacleReachEnv is planar only (the solver's disc contact is planar); "
                             "use planar=True")
        if kwargs.get("observation_format") == "goal":
            raise ValueError("ObstacleReachEnv has no goal-conditioned format: its reward_contact is not "
                             "a function of the goal; use observation_format='flat' or 'dict'")
        super().__init__(design, **kwargs)
        self.half_thickness = arm_half_thickness(self.arm)
        self.contact_stiffness = resolve_contact_stiffness(self.arm, contact_stiffness)
        if self.obstacle_radius_range[1] >= 0.5 * self.arm.length:
            raise ValueError(f"obstacle_radius {self.obstacle_radius_range[1]} m must be smaller than "
                             f"half the arm's length ({0.5 * self.arm.length:.3f} m): the discs stand "
                             "between the base and a target within reach")
        self._discs = np.zeros((0, 3))
        self._rejected = False
        self._rejected_force = 0.0
        self._contact_row = (np.zeros(1), np.zeros(1, dtype=np.bool_), np.zeros(1))  # F, touching, reward

    # ------------------------------------------------------------------ layout

    def _observation_parts(self):
        parts = super()._observation_parts()
        goal = parts.pop("goal")
        r = self.reach
        parts["obstacles"] = (np.tile([-r, -r, 0.0], self.max_obstacles),
                              np.tile([r, r, r], self.max_obstacles))
        parts["goal"] = goal
        return parts

    def _fill_goal(self, obs):
        super()._fill_goal(obs)
        block = obs[self._slices["obstacles"]].reshape(self.max_obstacles, 3)
        n = len(self._discs)
        block[:n, :2] = self._discs[:, :2]
        block[:n, 2] = self._discs[:, 2] + self.half_thickness
        block[n:] = 0.0

    # ------------------------------------------------------------------ reset

    def _reset_task(self, options, start):
        options = check_options(options, ("target", "obstacles"))
        fixed_discs = self._given_discs(options["obstacles"]) if "obstacles" in options else None
        fixed_target = "target" in options
        if fixed_target:
            super()._reset_task({"target": options["target"]}, start)
        self._rejected, self._rejected_force = False, 0.0
        attempts = 1 if fixed_target and fixed_discs is not None else TASK_ATTEMPTS
        # The count is drawn once: redrawing it with the target would favour one disc, which
        # fits more often. Only where n discs find no place in all attempts (a start state
        # that leaves little room) are fewer tried.
        low, high = self.n_obstacles_range
        n = int(self.np_random.integers(low, high + 1))
        counts = range(n, low - 1, -1) if fixed_discs is None else (len(fixed_discs),)
        for count in counts:
            for _ in range(attempts):
                placed = self._draw_task(start, fixed_target, fixed_discs, count)
                if placed is not None:
                    return placed
        raise RuntimeError(f"no target and obstacle placement for {self.arm.name} in {attempts} draws "
                           f"(n_obstacles {self.n_obstacles_range}, obstacle_radius "
                           f"{self.obstacle_radius_range} m, clearance {self.clearance} m"
                           + (f", options {options!r}" if options else "") + ")")

    def _given_discs(self, value) -> np.ndarray:
        """``options["obstacles"]`` as an (n, 3) array of (x, y, obstacle radius), checked."""
        try:
            discs = np.asarray(value, dtype=float).reshape(-1, 3)
        except (TypeError, ValueError):
            discs = np.empty((0, 3))
        if not 1 <= len(discs) <= self.max_obstacles or not np.all(np.isfinite(discs)) \
                or np.any(discs[:, 2] <= 0) or np.any(np.abs(discs) > self.reach):
            raise ValueError(f"options['obstacles'] must be 1 to {self.max_obstacles} (x, y, radius) "
                             f"triples in m with radius > 0, each within ±{self.reach:.3f} m; "
                             f"got {value!r}")
        contact = discs[:, 2] + self.half_thickness
        if np.any(np.hypot(discs[:, 0], discs[:, 1]) <= contact):
            raise ValueError(f"options['obstacles'] {value!r}: a disc (grown by the arm's half-thickness "
                             f"{self.half_thickness:.4f} m) covers the base at the origin")
        return discs

    def _draw_task(self, start: solver.Equilibrium, fixed_target: bool, fixed_discs, n: int):
        """One draw of the target and ``n`` discs (Starting State); None if a stage fails."""
        arm, scene = self._sim_arm, self._scene
        pressures, avoid = None, start.positions
        if not fixed_target:
            pressures = self.np_random.uniform(0.0, 1.0, self.n_inputs) * self.p_max
            free = solver.solve(arm, pressures, scene, model=self.model, planar=True)
            if not free.converged:
                return None
            self._target[:] = free.tip
            avoid = np.vstack([avoid, free.positions])
            if self.contact == "forbid":
                # The ramp's backbones without discs, in steps of at most delta_scale·p_max
                # (whatever the action mode: the path one absolute step sweeps): discs clear
                # of them leave the ramp untouched, so it stays a contact-free way in.
                state = start
                for p in self._ramp(start.pressures, pressures, self.delta_scale):
                    state = solver.solve(arm, p, scene, model=self.model, planar=True, warm_start=state)
                    if not state.converged:
                        return None
                    avoid = np.vstack([avoid, state.positions])
        discs = fixed_discs if fixed_discs is not None else \
            self._place_discs(n, start.tip, self._target, avoid)
        if discs is None:
            return None
        scene = replace(scene, obstacles=tuple(
            solver.Disc(center=(float(x), float(y)), radius=float(r) + self.half_thickness,
                        stiffness=self.contact_stiffness, friction=self.friction)
            for x, y, r in discs))
        eq = solver.solve(arm, start.pressures, scene, model=self.model, planar=True, warm_start=start)
        if not eq.converged:
            return None
        if not fixed_target:
            # From the start state, not cold: the solver's cold path loads the straight arm
            # with the discs in place, and a disc can catch it as it droops — a branch the
            # episode's arm, which starts drooped and clear of the discs, may never reach.
            # Stepped as the episode's arm steps (a Stepper: its lean contact path, and where
            # that cannot, solve() from the previous state; the same equilibria to the
            # solver's tolerance), at a fraction of the general contact path's cost.
            ramp = solver.Stepper(arm, scene, model=self.model, planar=True)
            ramp.adopt(eq)
            step = self.delta_scale if self.action_mode == "delta" else None
            for p in self._ramp(start.pressures, pressures, step):
                if not ramp.step(p).converged or (self.contact == "forbid" and ramp.equilibrium.in_contact):
                    return None
            if self._gap(ramp.tip[None], discs) < self.clearance:
                return None
            self._target[:] = ramp.tip
        self.target_pressures_pa = None if fixed_target else pressures
        self._discs = np.array(discs, dtype=float)
        return scene, eq

    def _ramp(self, start: np.ndarray, end: np.ndarray, step: float | None) -> list[np.ndarray]:
        """Pressures (Pa) of the straight ramp from ``start`` to ``end`` in the fewest equal
        steps of at most ``step``·p_max on every channel (one step for None)."""
        n = 1
        if step is not None:
            n = max(1, math.ceil(float(np.max(np.abs(end - start))) / (step * self.p_max) - 1e-9))
        return [start + (end - start) * (k / n) for k in range(1, n + 1)]

    def _gap(self, points: np.ndarray, discs: np.ndarray) -> float:
        """Smallest distance (m) from ``points`` (m, 2) to the contact circles of ``discs``
        (n, 3: x, y, obstacle radius)."""
        return float(np.min(self._gaps(points, discs)))

    def _gaps(self, points: np.ndarray, discs: np.ndarray) -> np.ndarray:
        """(m, n) distances (m) from each of ``points`` (m, 2) to the contact circle of each of
        ``discs`` (n, 3: x, y, obstacle radius)."""
        distance = np.hypot(points[:, None, 0] - discs[None, :, 0], points[:, None, 1] - discs[None, :, 1])
        return distance - discs[None, :, 2] - self.half_thickness

    def _place_discs(self, n: int, tip: np.ndarray, target: np.ndarray,
                     avoid: np.ndarray) -> np.ndarray | None:
        """``n`` discs (n, 3) across the segment from the start ``tip`` to ``target``, clear of
        the base, the target, ``avoid`` (backbone samples, m) and each other by ``clearance``;
        None if one finds no place.

        Each disc tries up to DISC_ATTEMPTS random placements (radius, offset across the
        segment, place along it: three draws each) and takes the first that fits. The
        attempts are drawn and tested at once (a reset's placements, one at a time, were a
        sixth of an obstacle-reach reset), and the generator is then advanced by exactly the
        draws the attempts up to the one taken used, so the episode is the one-at-a-time
        loop's: same discs, same later draws."""
        rng = self.np_random
        way = target - tip
        length = float(np.hypot(*way))
        if length == 0.0:
            return None
        across = np.array([-way[1], way[0]]) / length
        # Forbidden contact keeps the discs off the ramp's sweep, which covers the segment's
        # middle: they may then stand up to half the segment's length aside.
        spread = 0.5 * length if self.contact == "forbid" else 0.0
        discs = np.empty((0, 3))
        points = np.vstack([np.zeros((1, 2)), target[None], avoid])  # base, target, avoid
        low, high = self.obstacle_radius_range
        first, last = PLACEMENT_SPAN
        for _ in range(n):
            state = rng.bit_generator.state
            draws = rng.random((DISC_ATTEMPTS, 3))  # as rng.uniform(a, b): a + (b − a)·u
            radius = low + (high - low) * draws[:, 0]
            contact = radius + self.half_thickness
            offset = (-1.0 + 2.0 * draws[:, 1]) * (contact + spread)
            centers = tip + (first + (last - first) * draws[:, 2])[:, None] * way \
                + offset[:, None] * across
            candidates = np.column_stack([centers, radius])
            fits = ~(np.min(self._gaps(points, candidates), axis=0) < self.clearance)
            if len(discs):
                fits &= ~(np.min(self._gaps(centers, discs), axis=1) - contact < self.clearance)
            if not fits.any():
                return None  # every attempt's draws spent, as the loop spent them
            taken = int(np.argmax(fits))
            rng.bit_generator.state = state
            rng.random(3 * (taken + 1))
            discs = np.vstack([discs, candidates[taken:taken + 1]])
        return discs

    # ------------------------------------------------------------------ step

    def _advance(self, pressures):
        if self.contact == "penalize":
            return super()._advance(pressures)
        previous = self._stepper.equilibrium
        report, accepted = super()._advance(pressures)
        penetration, force = self._contact_state()
        self._rejected = accepted and penetration > 0.0
        if self._rejected:
            self._rejected_force = force
            self._stepper.adopt(previous)
        return report, accepted and not self._rejected

    def _contact_state(self) -> tuple[float, float]:
        """The current state's deepest penetration (m) and total contact force (N): from the
        solver's record where the stepper keeps one, else from the equilibrium."""
        stepper = self._stepper
        if stepper.record is not None:
            return stepper.contact_measures()
        return equilibrium_contact(self._eq)

    def contact_reward(self, eq: solver.Equilibrium) -> tuple[float, float]:
        """``reward_contact`` of an equilibrium a step reached, and its total contact force (N).

        The rule of the env card's Rewards, for this env's weights, before a forbidden contact
        is rejected (planners evaluate it on model rollouts;
        :func:`softarm_gym.envs.terms.contact_rewards`): ``penalize``: −contact_weight·F;
        ``forbid``: −contact_penalty if ``eq`` touches a disc, else 0.
        """
        force = total_contact_force(eq)
        return self._contact_term(force, eq.in_contact), force

    def _contact_term(self, force: float, touching: bool) -> float:
        """:func:`~softarm_gym.envs.terms.contact_rewards` of a batch of one."""
        forces, touches, out = self._contact_row
        forces[0] = force
        touches[0] = touching
        contact_rewards(forces, touches, self.contact == "forbid", self.contact_weight,
                        self.contact_penalty, out)
        return float(out[0])

    def _task_reward(self, converged):
        terms, success, info = super()._task_reward(converged)
        solver_term = terms.pop("reward_solver")
        penetration, force = self._contact_state()
        in_contact = penetration > 0.0
        if self._rejected:
            force = self._rejected_force
        contact = self._contact_term(force, self._rejected or in_contact)
        terms["reward_contact"] = contact
        terms["reward_solver"] = solver_term
        # Fixed shapes (one row per slot, unused rows zero, as in the observation) so that
        # vector envs can stack the infos of episodes with different disc counts.
        n = len(self._discs)
        discs = np.zeros((self.max_obstacles, 3))
        discs[:n] = self._discs
        radii = np.zeros(self.max_obstacles)
        radii[:n] = self._discs[:, 2] + self.half_thickness
        info.update({
            "obstacles": discs, "contact_radii": radii, "n_obstacles": n, "contact_force": force,
            "penetration": penetration, "in_contact": in_contact,
            "contact_rejected": bool(self._rejected)})
        self._rejected = False
        return terms, success, info

    def _task_artists(self):
        return {"target": self._target,
                "obstacles": [(disc[:2], disc[2]) for disc in self._discs]}

    def _caption(self):
        force = total_contact_force(self._eq)
        return super()._caption() + (f"\ncontact {force:.2f} N" if force else "")
