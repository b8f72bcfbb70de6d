"""Reach: bring the arm's tip to a target point (``SoftArm/OctArmReach-v0``, ``SoftArm/CTReach-v0``)."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

import solver
from softarm_gym.envs.base import SoftArmEnv
from softarm_gym.envs.config import check_options, finite_number
from softarm_gym.envs.terms import (
    REACH_TERMS,
    fill_reach_goals,
    goal_rewards,
    reach_reward_sum,
    reach_rewards,
)

__all__ = ["ReachEnv"]

TARGET_ATTEMPTS = 20
"""Random pressure draws tried for a target before reset gives up (a draw whose cold solve
does not converge is redrawn)."""


class ReachEnv(SoftArmEnv):
    """Reach a target with the tip of a multi-section pneumatic soft arm (planar, quasi-static).

    ## Description

    A soft arm (OctArm V, OctArm VI or the continuous-tube "CT" arm of Trivedi 2010) is clamped
    at the origin at ``base_angle_deg`` from the downward vertical (90 = horizontal along +x)
    and loaded by its own weight and a tip payload. Each step sets the channel pressures and
    the arm moves to the quasi-static equilibrium reached from the previous one (a Cosserat
    rod solved by shooting, warm-started, so snap-through and hysteresis are physical).
    The agent sees the arm only through a shape estimator fed with synthesised sensors.

    ## Action Space

    ``Box(-1, 1, (n_inputs,), float32)``: one normalised pressure per planar channel, in the
    order of ``arm.input_names(planar=True)`` — OctArm ``[s1_I, s1_II+III, s2_I, s2_II+III,
    s3_I, s3_II+III]``, CT ``[inner_I, inner_II+III, outer_I, outer_II+III]``. Channel I bends
    its section clockwise. ``action_mode="absolute"``: p = (a + 1)/2 · p_max;
    ``"delta"``: p ← clip(p + a · delta_scale · p_max, 0, p_max). p_max is the design's rated
    pressure: OctArm V 100 psi (689.5 kPa), OctArm VI 90 psi (620.5 kPa), CT 70 psi (482.6 kPa).
    Values outside [-1, 1] are clipped; a NaN or infinite value raises ``ValueError`` naming
    the channel.

    ## Observation Space

    Flat ``Box(float32)`` (``observation_format="flat"``, works with SB3 ``MlpPolicy``) or a
    ``Dict`` of the same blocks (``"dict"``), in this order:

    | block | size | meaning | unit |
    |---|---|---|---|
    | ``tip`` | 2 | estimated tip (x, y) | m |
    | ``section_ends`` | 4·n_sections | per section end: x, y, cos θ, sin θ (θ of d3 from +x) | m, – |
    | ``backbone`` | 2·n_backbone | estimated backbone, even in reference arc length, base to tip | m |
    | ``pressures`` | n_inputs | current channel pressures on the action scale, 2p/p_max − 1 | – |
    | ``goal`` | 4 | target (x, y), then target − estimated tip | m |

    ``observation_format="goal"`` gives the goal-conditioned layout of Gymnasium-Robotics
    (SB3 ``MultiInputPolicy``, ``HerReplayBuffer``): ``Dict(observation, achieved_goal,
    desired_goal)``, where ``observation`` is the flat observation without its ``goal`` block
    (``tip`` … ``pressures``, float32), ``achieved_goal`` the true tip and ``desired_goal`` the
    target (``Box(−2L, 2L, (dim,), float64)``, m, unclipped: the very numbers the reward
    uses). It needs ``observation="true"`` (``ValueError`` otherwise): ``achieved_goal`` is
    the true tip, which an agent under test with an estimator must not see.
    :meth:`compute_reward` gives the reward of any (achieved, desired) pair.

    With ``planar=False`` positions are (x, y, z), section ends (x, y, z, d3x, d3y, d3z) and the
    goal (target, target − tip) 6 values. Positions are bounded by ±2L (L the arm's length)
    and clipped to it. Estimates come from
    ``observation``: ``true`` (the equilibrium itself), ``model`` (nominal arm at the
    commanded pressures, payload assumed 0), ``constant_curvature`` (encoder lengths),
    ``cable_encoder``, ``inclinometer`` or ``load_cell`` (thesis chapter 4). Estimators use the
    nominal design even when the simulated arm is randomised.

    ## Rewards

    ``reward = reward_distance + reward_control + reward_success + reward_solver``, each in
    ``info``: ``reward_distance = −distance_weight · |tip_true − target|`` (m, the true tip);
    ``reward_control = −control_weight · mean((p/p_max)²)`` (an air-consumption cost, the same
    in both action modes); ``reward_success = success_bonus`` while the true tip is within
    ``success_tolerance`` (default 2 cm ≈ L/40 for OctArm V), else 0; ``reward_solver =
    −solver_failure_penalty`` on a step whose equilibrium did not converge, else 0.
    ``compute_reward(achieved_goal, desired_goal, info)`` recomputes the two goal terms and
    reproduces the reward exactly (see its docstring), for hindsight relabelling.

    ## Starting State

    Per episode: the simulated arm (``randomization``), a payload drawn uniformly from
    ``payload_kg``, a target — the tip of the arm at uniformly random pressures, solved
    cold (the solver follows the quasi-static path from rest), so every target is
    reachable by this episode's arm and payload (or
    ``options={"target": (x, y)}``; a target farther from the base than the arm fully stretched
    at the rated pressure raises ``ValueError``, as does any other option key) — and start
    pressures uniform in
    [0, ``initial_pressure_fraction``]·p_max.

    ## Episode End

    Truncated at ``max_episode_steps`` (``gym.make`` kwarg; registered default 100) or after
    ``max_solver_failures`` consecutive unconverged steps (default 5). An unconverged step
    keeps the last converged equilibrium and its pressures (``info["converged"] = False``,
    ``reward_solver`` applies). Terminated on success only with ``terminate_on_success=True``.

    ## Arguments

    ``gym.make("SoftArm/OctArmReach-v0", **kwargs)``:

    * ``design`` (``"octarm_v"``; CTReach ``"ct"``): design name or ``solver.designs.ArmDesign``.
    * ``planar`` (True): the planar model. ``False``: the spatial arm — one pressure per
      spatial channel (OctArm ``s1_I, s1_II, s1_III, ...``, CT ``inner_I, ..., outer_III``),
      3-D positions, section ends as (x, y, z, d3) and a 3-D target; the ``inclinometer``
      estimator reads IMUs at the base and section ends (tilt and heading; ``info["sensors"]``
      adds ``imu``); rendering shows the arm in 3D (see ``render_mode``).
    * ``observation`` (``"true"``): the shape estimator, one of ``softarm_gym.sensing.ESTIMATORS``.
    * ``sensor_noise`` (``"off"``): ``"off"``, ``"thesis"`` (Table 4.3 resolutions), a dict of
      ``SensorNoise`` fields or a ``SensorNoise``.
    * ``base_angle_deg`` (90): base orientation from the downward vertical (deg).
    * ``gravity`` (9.81 m/s²; 0 switches self-weight and payload weight off).
    * ``payload_kg`` (0): tip payload (kg), a number or a ``(low, high)`` range drawn per
      episode; unknown to the ``model`` estimator.
    * ``randomization`` (None): ``{"wind_angle_deg": 2.0, "youngs_modulus_rel": 0.1}`` draws
      α ± 2° and E ± 10 % per episode for the simulated arm (``ArmRandomization``);
      ``"fit.json"`` (a ``softarm fit --output`` file) draws the arm from the fitted
      parameters' posterior (``PosteriorRandomization``, docs/identification.md).
    * ``action_mode`` (``"absolute"``; the ``-v1`` ids ``"delta"``) and ``delta_scale`` (0.1
      of p_max per step).
    * ``n_backbone`` (8): backbone samples in the observation.
    * ``observation_format`` (``"flat"``), ``"dict"`` or ``"goal"`` (``observation="true"`` only).
    * ``distance_weight`` (1), ``control_weight`` (0.01), ``success_bonus`` (1),
      ``success_tolerance`` (0.02 m), ``solver_failure_penalty`` (1), ``max_solver_failures`` (5),
      ``terminate_on_success`` (False).
    * ``initial_pressure_fraction`` (0.1), ``model`` (``"full"``, the simulator's rod model).
    * ``actuation`` (``"ideal"``: the channels take the commanded pressures at once) or
      ``"lag"``: each channel pressure follows its command through a first-order lag,
      p ← p + (1 − e^(−dt/τ))·(p_command − p) per step, with ``pressure_time_constant_s`` τ
      (0.2 s) and ``step_dt_s`` dt (0.1 s); the arm is quasi-static at every step. The
      ``pressures`` block is then the measured pressures, a ``commanded`` block (same scale)
      follows it, ``delta`` actions increment the command, and ``info`` adds
      ``commanded_pressures_pa``. τ is an assumed order of magnitude, not a thesis figure
      (docs/environments.md, "Pneumatic lag").
    * ``self_contact`` (False): parts of the arm farther apart along it than three arm
      thicknesses press on each other instead of passing through (planar, ``model`` ``"full"``
      or ``"unshearable"``): True uses the tubes' ring stiffness as the penalty (the wrap
      envs' contact law), a number sets it (N/m²). Where no part comes near another the step
      costs nothing more; where parts touch, a step is a contact solve (docs/design.md §9).
    * ``self_friction`` (0: frictionless): the Coulomb coefficient μ ≥ 0 between parts of
      the arm pressed on each other (``solver.Scene.self_friction``, docs/design.md §9.1);
      needs ``self_contact``. Separate from the contact envs' ``friction`` (arm on object):
      rubber on rubber and rubber on an object differ, and the registered ids keep 0.
    * ``synthesize_sensors`` (None): synthesise sensor readings every step. By default only
      when the observation's estimator reads them (not for ``true`` and ``model``, which
      need none — skipping them is most of a ``true`` step's saving); True forces them into
      ``info["sensors"]``.
    * ``render_mode`` (None, ``"rgb_array"`` or ``"human"``), ``render_size`` (400 px, at most 4096).
      A planar arm is drawn in the x–y plane; a spatial one (``planar=False``) in three
      orthographic views — front (x–y), side (z–y) and top (x–z), axes in metres — with the
      target at its 3-D position, in a frame of the same size.

    ## Info

    ``tip_true`` (m), ``tip_estimated`` (m), ``estimation_error`` (m, |estimated − true tip|),
    ``sensors`` (dict of the raw ``SensorReadings`` arrays, empty when none are synthesised
    — see ``synthesize_sensors``: ``encoder_lengths`` (m),
    ``inclinometers`` (rad), ``base_wrench`` (N, N m)), ``converged``, ``solver`` (converged, iterations,
    residual, stable, snapped of the attempted solve), ``solver_failures``, ``pressures_pa``,
    ``payload_kg``, ``target``, ``distance`` (m), ``is_success`` and the ``reward_*`` terms.
    ``env.unwrapped.target_pressures_pa`` holds the pressures (Pa) whose cold equilibrium
    placed the target (None for a target given in ``options``): for analysis, not observed.

    ## Version History

    * v0: initial version.
    * v1: delta actions by default (``action_mode="delta"``, ``delta_scale=0.1``), the
      configuration the shipped SAC models were trained in; otherwise equal to v0.
    """

    def __init__(self, design="octarm_v", *, distance_weight: float = 1.0, control_weight: float = 0.01,
                 success_bonus: float = 1.0, success_tolerance: float = 0.02,
                 terminate_on_success: bool = False, **kwargs):
        self.distance_weight = finite_number("distance_weight", distance_weight, 0.0)
        self.control_weight = finite_number("control_weight", control_weight, 0.0)
        self.success_bonus = finite_number("success_bonus", success_bonus, 0.0)
        self.success_tolerance = finite_number("success_tolerance", success_tolerance, 0.0)
        if self.success_tolerance <= 0:
            raise ValueError(f"success_tolerance must be > 0 (m); got {success_tolerance}")
        self.terminate_on_success = bool(terminate_on_success)
        self.target_pressures_pa = None
        observation = kwargs.get("observation", "true")
        if kwargs.get("observation_format") == "goal" and observation != "true":
            raise ValueError(f"observation_format='goal' needs observation='true' (got {observation!r}): "
                             "its achieved_goal is the true tip, which would bypass the estimator")
        super().__init__(design, **kwargs)
        self._target = np.zeros(self.dim)
        # One-row buffers of the batch-first reward (softarm_gym.envs.terms.reach_rewards).
        self._terms = np.zeros((1, len(REACH_TERMS)))
        self._distance = np.zeros(1)
        self._success = np.zeros(1, dtype=np.bool_)
        self._converged = np.zeros(1, dtype=np.bool_)

    def _goal_bounds(self):
        r = self.reach
        high = np.concatenate([np.full(self.dim, r), np.full(self.dim, 2 * r)])
        return -high, high

    def _goal_spaces(self):
        r = self.reach
        box = spaces.Box(-r, r, shape=(self.dim,), dtype=np.float64)
        return box, box

    def _goals(self):
        return self._stepper.tip.copy(), self._target.copy()

    @property
    def compute_reward(self):
        """``compute_reward(achieved_goal, desired_goal, info)``: the goal-conditioned reward
        (:meth:`_compute_reward`), only with ``observation_format="goal"``. SB3 and
        Gymnasium-Robotics take an env with this attribute for a goal env, so in the other
        formats it does not exist (``AttributeError``)."""
        if self.observation_format != "goal":
            raise AttributeError("compute_reward exists only with observation_format='goal'")
        return self._compute_reward

    def _compute_reward(self, achieved_goal, desired_goal, info):
        """The reward of reaching ``desired_goal`` with the tip at ``achieved_goal``, vectorised.

        For hindsight relabelling (SB3 ``HerReplayBuffer``). It recomputes the two terms that
        depend on the goal — ``reward_distance = −distance_weight · |achieved − desired|`` and
        ``reward_success = success_bonus`` if that distance is within ``success_tolerance``,
        else 0 — with the kernel the step uses, and takes the two that do not from ``info``:
        ``reward_control`` (the pressures) and ``reward_solver`` (the solve). The terms are
        summed in the step's order, so for a step's own goals and info the result equals the
        step's reward bit for bit.

        Args:
            achieved_goal, desired_goal: (..., dim) true tips and targets (m).
            info: one step's info dict (its two terms scalars, or arrays of the batch shape, as
                a vector env gives them), or an array or sequence of info dicts of the batch
                shape, one per transition — what ``HerReplayBuffer(copy_info_dict=True)``
                passes (without ``copy_info_dict`` it passes empty dicts).

        Returns:
            A float for goals of shape (dim,), else an array of the batch shape (...).

        Raises:
            ValueError: goals of different shapes or not ending in ``dim``; infos missing a
                term or not matching the batch shape.
        """
        achieved = np.asarray(achieved_goal, dtype=np.float64)
        desired = np.asarray(desired_goal, dtype=np.float64)
        if achieved.shape != desired.shape or achieved.ndim == 0 or achieved.shape[-1] != self.dim:
            raise ValueError(f"achieved_goal and desired_goal must both have shape (..., {self.dim}); got "
                             f"{achieved.shape} and {desired.shape}")
        batch = achieved.shape[:-1]
        n = math.prod(batch)
        terms = np.empty((n, len(REACH_TERMS)))
        goal_rewards(np.ascontiguousarray(achieved.reshape(n, self.dim)),
                     np.ascontiguousarray(desired.reshape(n, self.dim)), self.distance_weight,
                     self.success_bonus, self.success_tolerance, terms, np.empty(n),
                     np.empty(n, dtype=np.bool_))
        terms[:, 1], terms[:, 3] = _goal_free_terms(info, batch)
        reward = reach_reward_sum(terms).reshape(batch)
        return float(reward) if not batch else reward

    def _reset_task(self, options, start):
        options = check_options(options, ("target",))
        if "target" in options:
            try:
                target = np.asarray(options["target"], dtype=float)
            except (TypeError, ValueError):
                target = None
            if target is None or target.shape != (self.dim,) or not np.all(np.isfinite(target)):
                raise ValueError(f"options['target'] must be a finite {self.dim}-D point (m); "
                                 f"got {options['target']!r}")
            # No pressure stretches a section beyond its stretch with every channel at p_max, so
            # a target farther than that (plus the success tolerance) from the base can never be
            # reached; the observation would also clip it silently.
            stretch = solver.rest_strains(self._sim_arm, np.full(self._sim_arm.n_channels, self.p_max))[2]
            limit = min(float(sum(s.length * v for s, v in zip(self._sim_arm.sections, stretch)))
                        + self.success_tolerance, self.reach)
            distance = float(np.linalg.norm(target))
            if distance > limit:
                raise ValueError(f"options['target'] {tuple(target.tolist())} is {distance:.3g} m from the "
                                 f"base; {self.arm.name} reaches at most {limit:.3f} m (every section "
                                 "fully stretched at the rated pressure)")
            self._target[:] = target
            self.target_pressures_pa = None
            return self._scene, start
        for _ in range(TARGET_ATTEMPTS):
            fraction = self.np_random.uniform(0.0, 1.0, self.n_inputs)
            eq = solver.solve(self._sim_arm, fraction * self.p_max, self._scene, model=self.model,
                              planar=self.planar, record=False)
            if eq.converged:
                self._target[:] = eq.tip
                self.target_pressures_pa = eq.pressures.copy()
                return self._scene, start
        raise RuntimeError(f"no converged target in {TARGET_ATTEMPTS} random pressure draws for "
                           f"{self.arm.name} in {self._scene}")

    def _fill_goal(self, obs):
        fill_reach_goals(self._target[None], self._tip_row, self._slices["goal"].start, obs[None])

    def _task_reward(self, converged):
        reach_rewards(self._stepper.tip[None], self._target[None],
                      self._fraction[None], self._converged_row(converged),
                      self.distance_weight, self.control_weight, self.success_bonus,
                      self.success_tolerance, self.solver_failure_penalty, self._terms,
                      self._distance, self._success)
        t = self._terms[0]
        distance = float(self._distance[0])
        terms = {REACH_TERMS[0]: float(t[0]), REACH_TERMS[1]: float(t[1]),
                 REACH_TERMS[2]: float(t[2]), REACH_TERMS[3]: float(t[3])}
        return terms, bool(self._success[0]), {"target": self._target.copy(), "distance": distance}

    def _converged_row(self, converged):
        self._converged[0] = converged
        return self._converged

    def _terminated(self, success):
        return self.terminate_on_success and success

    def _task_artists(self):
        return {"target": self._target}

    def _caption(self):
        return super()._caption() + f"\ndistance {1000 * math.dist(self._stepper.tip, self._target):.1f} mm"


_GOAL_FREE = (REACH_TERMS[1], REACH_TERMS[3])
"""The reward terms that do not depend on the goal (``reward_control``, ``reward_solver``)."""


def _goal_free_terms(info, batch: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """``reward_control`` and ``reward_solver`` of ``info`` as flat arrays of ``prod(batch)`` values."""
    n = math.prod(batch)
    missing = ("compute_reward needs info['reward_control'] and info['reward_solver'] (the terms that "
               "do not depend on the goal); SB3's HerReplayBuffer passes them only with "
               "replay_buffer_kwargs={'copy_info_dict': True}")
    if isinstance(info, dict):
        try:
            return tuple(np.broadcast_to(np.asarray(info[key], dtype=np.float64), batch).reshape(n)
                         for key in _GOAL_FREE)
        except KeyError:
            raise ValueError(missing) from None
        except ValueError:
            raise ValueError(f"info's reward terms do not fit the goals' batch shape {batch}") from None
    infos = np.asarray(info, dtype=object)
    if infos.shape != batch:
        raise ValueError(f"info must be one dict or one dict per transition, shape {batch}; got shape "
                         f"{infos.shape}")
    try:
        return tuple(np.fromiter((i[key] for i in infos.reshape(n)), dtype=np.float64, count=n)
                     for key in _GOAL_FREE)
    except (KeyError, TypeError):
        raise ValueError(missing) from None
