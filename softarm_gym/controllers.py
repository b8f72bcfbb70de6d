"""Classical comparisons for the RL baselines: a damped-least-squares Jacobian controller (reach)
and a scripted curl (wrap).

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
fractions, J_f = J·p_max (m per unit fraction), and commands f ← f + Δf with

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

import numpy as np
from scipy.optimize import lsq_linear

import solver
from softarm_gym.analysis import jacobian

__all__ = ["JacobianController", "CurlController", "observation_slices"]


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
            current = 0.5 * (obs[self._slices["pressures"]] + 1.0)
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

    Args:
        env: a (possibly wrapped) planar wrap environment with ``observation_format='flat'``.
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
        lengths = np.array([section.length for section in base.arm.sections])
        turning = np.empty(base.n_inputs)
        for k in range(base.n_inputs):
            pressures = np.zeros(base.n_inputs)
            pressures[k] = base.arm.max_pressure
            channels = solver.channel_pressures(base.arm, pressures, planar=True)
            _, u2, _ = solver.rest_strains(base.arm, channels)
            turning[k] = u2 @ lengths
        self.turning = turning
        """Total rest turning (rad) of the arm with each input alone at p_max (> 0: counter-clockwise)."""
        self.reset()

    def reset(self) -> None:
        """Forget the side, the last command and the step size (call at every episode start)."""
        self._inputs = None
        self._command = None
        self._increment = 1.0 / self.ramp_steps

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
            self._inputs = (np.sign(self.turning) == self._side(obs)).astype(float)
        # The observation is float32: a command the env took matches it to ~1e-7.
        elif np.max(np.abs(current - self._command)) > 1e-5:
            # Rejected: hold the accepted state for a step (so the env's run of consecutive
            # failures ends), then go on with half the step.
            self._increment *= 0.5
            self._command = current
            return self._command
        # Below a thousandth of p_max the next rejection could not be seen: stop and hold.
        increment = self._increment if self._increment >= _MIN_INCREMENT else 0.0
        step = np.where(self._inputs > 0, increment, -increment)
        self._command = np.clip(current + step, 0.0, 1.0)
        return self._command
