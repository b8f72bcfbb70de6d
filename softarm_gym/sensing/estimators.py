"""Shape estimators: sensor readings (and commanded pressures) → backbone shape (chapter 4).

All estimators return one :class:`ShapeEstimate` and share one interface::

    est = make_estimator("cable_encoder", arm, planar=True, scene=solver.Scene(...))
    est.reset()                                    # new episode: forget warm starts
    shape = est.estimate(readings, pressures_pa)   # readings from sensing.synthesize

An estimator knows the *nominal* design it was built with and the mounting (base angle,
gravity) of ``scene``; it never sees the true payload or external loads of ``scene`` (those
are what it has to cope with), nor a randomised simulated arm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

import solver
from softarm_gym.sensing.kernels import (
    CABLE_DATA,
    IMU_DATA,
    REDUCED_STATE,
    load_cell_planar,
    load_cell_spatial,
    planar_shape,
    reduced_planar,
    reduced_residual,
    reduced_spatial,
    reduced_spatial_newton,
    reduced_spatial_residual,
)
from softarm_gym.sensing.sensors import SensorReadings, cable_angles, cable_radius, imu_frames
from solver.layout import NSTATE
from solver.rod import (
    arc_chain_planar,
    arc_chain_spatial,
    base_rotation,
    hermite_resample,
    rotation_to_quaternion,
)

__all__ = ["ShapeEstimate", "Estimator", "make_estimator", "ESTIMATORS", "shape_from_equilibrium"]

ESTIMATORS = ("true", "model", "constant_curvature", "cable_encoder", "inclinometer", "load_cell")
"""Names accepted by :func:`make_estimator`."""

DEFAULT_SAMPLES = 32


@dataclass(frozen=True)
class ShapeEstimate:
    """An estimated backbone.

    Attributes:
        tip: (2,) planar or (3,) spatial tip position (m).
        section_ends: (n_sections, 3): planar (x, y, θ) of each section end (m, m, rad);
            spatial (x, y, z) (m).
        backbone: (K, 2|3) positions at K reference arc lengths evenly spaced from the base
            (s = 0) to the tip (s = L) (m).
        section_frames: spatial (n_sections, 3, 3) directors [d1 d2 d3] (columns) at each
            section end; planar: empty (0, 3, 3).
        converged: False when an iterative estimator stopped short of its tolerance (the
            estimate is then its last iterate).
    """

    tip: np.ndarray
    section_ends: np.ndarray
    backbone: np.ndarray
    section_frames: np.ndarray = field(default_factory=lambda: np.empty((0, 3, 3)))
    converged: bool = True

    def __post_init__(self):
        tip = np.array(self.tip, dtype=float)
        ends = np.array(self.section_ends, dtype=float)
        backbone = np.array(self.backbone, dtype=float)
        frames = np.array(self.section_frames, dtype=float)
        if tip.shape not in ((2,), (3,)):
            raise ValueError(f"ShapeEstimate.tip must have shape (2,) or (3,); got {tip.shape}")
        dim = tip.shape[0]
        if ends.ndim != 2 or ends.shape[1] != 3:
            raise ValueError(f"ShapeEstimate.section_ends must have shape (n_sections, 3); got {ends.shape}")
        if backbone.ndim != 2 or backbone.shape[1] != dim or backbone.shape[0] < 2:
            raise ValueError(f"ShapeEstimate.backbone must have shape (K >= 2, {dim}); got {backbone.shape}")
        if dim == 3 and frames.shape != (ends.shape[0], 3, 3):
            raise ValueError(f"spatial ShapeEstimate.section_frames must have shape "
                             f"({ends.shape[0]}, 3, 3); got {frames.shape}")
        for arr in (tip, ends, backbone, frames):
            arr.setflags(write=False)
        object.__setattr__(self, "tip", tip)
        object.__setattr__(self, "section_ends", ends)
        object.__setattr__(self, "backbone", backbone)
        object.__setattr__(self, "section_frames", frames)

    @property
    def planar(self) -> bool:
        """True for a planar estimate."""
        return self.tip.shape[0] == 2


def shape_from_equilibrium(eq: solver.Equilibrium, n_samples: int = DEFAULT_SAMPLES) -> ShapeEstimate:
    """The :class:`ShapeEstimate` of a recorded equilibrium (cubic Hermite backbone resampling).

    Args:
        eq: an equilibrium solved with ``record=True``.
        n_samples: K, number of backbone samples.
    """
    if eq.s.size == 0:
        raise ValueError("the equilibrium was solved with record=False; solve with record=True")
    ends = np.asarray(eq.section_ends, dtype=np.int64)
    s_query = np.linspace(0.0, float(eq.s[-1]), n_samples)
    if eq.planar:
        backbone = np.empty((n_samples, 2))
        section_ends = np.empty((ends.shape[0], 3))
        planar_shape(eq.s, eq.positions, eq.angles, eq.shear_stretch, ends, s_query, backbone,
                     section_ends, np.empty((eq.s.shape[0], 2)))
        return ShapeEstimate(tip=eq.tip, section_ends=section_ends, backbone=backbone,
                             converged=bool(eq.converged))
    tangent = np.einsum("nij,nj->ni", eq.orientations, eq.shear_stretch)
    section_ends = eq.positions[ends]
    frames = eq.orientations[ends]
    backbone = np.empty((n_samples, eq.positions.shape[1]))
    hermite_resample(np.ascontiguousarray(eq.s), np.ascontiguousarray(eq.positions),
                      np.ascontiguousarray(tangent), s_query, backbone)
    backbone[-1] = eq.tip
    return ShapeEstimate(tip=eq.tip, section_ends=section_ends, backbone=backbone,
                         section_frames=frames, converged=bool(eq.converged))


class Estimator:
    """Base class: holds the nominal design, mode, mounting scene and sample count.

    Subclasses implement :meth:`_estimate`; :meth:`estimate` validates the inputs first.
    """

    name = ""
    reads_sensors = True
    """False for estimators that ignore the readings (``true``, ``model``): callers may then
    pass ``readings=None`` and skip synthesising them."""

    def __init__(self, arm: solver.designs.ArmDesign, planar: bool, scene: solver.Scene,
                 n_samples: int):
        self.arm = arm
        self.planar = bool(planar)
        self.scene = scene
        self.n_samples = n_samples
        self.s_query = np.linspace(0.0, arm.length, n_samples)
        self.sec_len = np.array([s.length for s in arm.sections])

    def reset(self) -> None:
        """Forget any state carried between estimates (start of a new episode)."""

    def estimate(self, readings: SensorReadings, pressures_pa, truth: solver.Equilibrium | None = None
                 ) -> ShapeEstimate:
        """Estimate the shape.

        Args:
            readings: sensor readings of the current equilibrium (:func:`synthesize`); may be
                None for an estimator that does not read them (``reads_sensors`` False).
            pressures_pa: (n_inputs,) commanded pressures (Pa), ordered as
                ``arm.input_names(planar)``.
            truth: the true equilibrium; used only by the ``true`` estimator.

        Returns:
            The :class:`ShapeEstimate`.
        """
        if readings is None and not self.reads_sensors:
            pass
        elif not isinstance(readings, SensorReadings):
            raise ValueError(f"readings must be SensorReadings; got {type(readings).__name__}")
        elif readings.planar != self.planar:
            raise ValueError(f"{self.name} estimator is {'planar' if self.planar else 'spatial'} but "
                             f"the readings are {'planar' if readings.planar else 'spatial'}")
        elif readings.encoder_lengths.shape[0] != len(self.arm.sections):
            raise ValueError(f"readings are for {readings.encoder_lengths.shape[0]} sections; design "
                             f"{self.arm.name!r} has {len(self.arm.sections)}")
        p = np.asarray(pressures_pa, dtype=float)
        if p.shape != (self.arm.n_inputs(self.planar),):
            raise ValueError(f"pressures_pa must have shape ({self.arm.n_inputs(self.planar)},) "
                             f"({', '.join(self.arm.input_names(self.planar))}); got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise ValueError("pressures_pa contains non-finite values")
        return self._estimate(readings, p, truth)

    def _estimate(self, readings, pressures, truth) -> ShapeEstimate:
        raise NotImplementedError


class TrueShape(Estimator):
    """Ground truth: the equilibrium itself (for reference and privileged observations)."""

    name = "true"
    reads_sensors = False

    def _estimate(self, readings, pressures, truth):
        if not isinstance(truth, solver.Equilibrium):
            raise ValueError("the 'true' estimator needs truth=<the solved Equilibrium>")
        if truth.planar != self.planar:
            raise ValueError("truth equilibrium and estimator differ in planar/spatial mode")
        return shape_from_equilibrium(truth, self.n_samples)


class ModelShape(Estimator):
    """The nominal model at the commanded pressures; payload and external loads unknown (0).

    Follows the quasi-static path from its previous estimate within an episode (warm start);
    :meth:`reset` forgets it. Readings are ignored.

    Options:
        model: solver model (``"full"``, ``"unshearable"``, ``"constant_curvature"``).
        settings: :class:`solver.Settings`.
    """

    name = "model"
    reads_sensors = False

    def __init__(self, arm, planar, scene, n_samples, model: str = "full",
                 settings: solver.Settings | None = None):
        super().__init__(arm, planar, scene, n_samples)
        if model not in solver.MODELS:
            raise ValueError(f"unknown model {model!r}; choose one of {', '.join(solver.MODELS)}")
        self.model = model
        self.settings = solver.Settings() if settings is None else settings
        self.nominal_scene = replace(scene, payload_kg=0.0, tip_force=(0.0, 0.0), tip_moment=0.0)
        self._previous: solver.Equilibrium | None = None

    def reset(self) -> None:
        self._previous = None

    def _estimate(self, readings, pressures, truth):
        eq = solver.solve(self.arm, pressures, self.nominal_scene, model=self.model,
                          planar=self.planar, warm_start=self._previous, settings=self.settings)
        self._previous = eq
        return shape_from_equilibrium(eq, self.n_samples)


class ConstantCurvatureShape(Estimator):
    """Each section a circular arc, its stretch and curvature from its encoder cables.

    Stretch and turning per section from :func:`cable_section_strains`; the base orientation
    from the base inclinometer (spatial: its tilt, with the mounting's heading d2 = +z).
    Exact when no load acts; gravity bends sections away from arcs (the §4.3 failure mode).
    """

    name = "constant_curvature"

    def __init__(self, arm, planar, scene, n_samples):
        super().__init__(arm, planar, scene, n_samples)
        self.radius = cable_radius(arm)

    def _estimate(self, readings, pressures, truth):
        stretch, turning = cable_section_strains(readings, self.sec_len, self.radius)
        curvature = turning / (self.sec_len if self.planar else self.sec_len[:, None])
        if self.planar:
            backbone = np.empty((self.n_samples, 2))
            ends = np.empty((len(self.sec_len), 3))
            arc_chain_planar(float(readings.inclinometers[0]), self.sec_len, curvature, stretch,
                             self.s_query, backbone, np.empty(0), ends)
            backbone[-1] = ends[-1, :2]
            return ShapeEstimate(tip=ends[-1, :2], section_ends=ends, backbone=backbone)
        ns = len(self.sec_len)
        backbone, ends, frames = np.empty((self.n_samples, 3)), np.empty((ns, 3)), np.empty((ns, 3, 3))
        arc_chain_spatial(base_rotation(float(readings.inclinometers[0, 0])), self.sec_len,
                          np.ascontiguousarray(curvature), stretch, self.s_query,
                          np.empty((4, 3, 3)), backbone, np.empty((0, 3, 3)), ends, frames)
        backbone[-1] = ends[-1]
        return ShapeEstimate(tip=ends[-1], section_ends=ends, backbone=backbone, section_frames=frames)


def cable_section_strains(readings: SensorReadings, sec_len: np.ndarray, radius: float):
    """Per-section stretch and turning angle from the cable encoders (no shear, uniform stretch).

    Section cable lengths are differences of the cumulative readings. Planar (cables at ±R·d1):
    l± = L0·v ∓ R·Δθ, so v = (l+ + l−)/(2L0), Δθ = (l− − l+)/(2R) (Eqs. 4.27–4.30 with a
    symmetric pair). Spatial (φ = 0°, 120°, 240°): l_k = L0·v + R(U1 sin φ_k − U2 cos φ_k)
    with U = ∫u ds over the section, solved exactly for (v, U1, U2).

    Returns:
        (stretch (ns,), turning: planar Δθ (ns,) or spatial (U1, U2) (ns, 2), rad).
    """
    lengths = np.diff(readings.encoder_lengths, axis=0, prepend=0.0)
    if readings.planar:
        return lengths.sum(axis=1) / (2.0 * sec_len), (lengths[:, 1] - lengths[:, 0]) / (2.0 * radius)
    phi = cable_angles(False)
    return lengths.mean(axis=1) / sec_len, np.column_stack(
        [lengths @ np.sin(phi), -(lengths @ np.cos(phi))]) / (1.5 * radius)


def damped_newton(residual, z: np.ndarray, unknown_scale: np.ndarray, tol: float, max_iter: int,
                  max_step: float = 20.0):
    """Newton with a forward-difference Jacobian and step halving, in place on ``z``.

    Steps are first clipped to ``max_step`` units of ``unknown_scale`` (as the solver clips
    its Newton steps, so that a poor guess cannot fling the iterate to a distant root: with a
    known payload, strongly curled arms admit other roots with large, opposing section
    shears), then halved (up to 20 times) until they reduce the residual's 2-norm (for which
    the Newton direction is a descent direction). Converged when max |residual| <= tol.

    Args:
        residual: z (n,) -> residuals (n,) in rad.
        z: initial guess, overwritten with the solution.
        unknown_scale: (n,) typical size of each unknown (sets its difference step).
        tol, max_iter: tolerance on max |residual| (rad) and iteration cap.
        max_step: largest step, in units of ``unknown_scale``.

    Returns:
        (converged, max |residual|).
    """
    res = residual(z)
    merit = float(res @ res)
    jac = np.empty((z.size, z.size))
    for it in range(max_iter + 1):
        err = float(np.max(np.abs(res)))
        if not np.isfinite(err):
            return False, math.inf
        if err <= tol:
            return True, err
        if it == max_iter:
            break
        for j in range(z.size):
            step = 1e-6 * unknown_scale[j]
            keep = z[j]
            z[j] = keep + step
            jac[:, j] = (residual(z) - res) / step
            z[j] = keep
        try:
            step = np.linalg.solve(jac, -res)
        except np.linalg.LinAlgError:
            return False, err
        step *= min(1.0, max_step / float(np.max(np.abs(step) / unknown_scale)))
        start = z.copy()
        scale = 1.0
        for _ in range(21):
            z[:] = start + scale * step
            trial = residual(z)
            trial_merit = float(trial @ trial)
            if trial_merit < merit:
                break
            scale *= 0.5
        res, merit = trial, trial_merit
    return False, float(np.max(np.abs(res)))


class _Integrating(Estimator):
    """An estimator that integrates the rod equations on RK4 nodes and resamples the backbone.

    Options:
        steps_per_section: RK4 steps per section (default: the solver's).
    """

    def __init__(self, arm, planar, scene, n_samples, steps_per_section: int | None = None):
        super().__init__(arm, planar, scene, n_samples)
        steps = solver.Settings().steps_per_section if steps_per_section is None else steps_per_section
        if isinstance(steps, bool) or int(steps) != steps or steps < 1:
            raise ValueError(f"steps_per_section must be an integer >= 1; got {steps!r}")
        ns = len(arm.sections)
        self.sec_steps = np.full(ns, int(steps), dtype=np.int64)
        rows = int(self.sec_steps.sum()) + ns
        dim = 2 if planar else 3
        self._s = np.empty(rows)
        self._pos = np.empty((rows, dim))
        self._tan = np.empty((rows, dim))
        self._ends = np.empty((ns, 3))
        self._frames = np.empty((0, 3, 3)) if planar else np.empty((ns, 3, 3))
        self.c_i = np.array([1.0 / s.EI for s in arm.sections])
        self.mass_per_length = np.array([s.mass_per_length for s in arm.sections])
        self.endplate = np.array([s.endplate_mass for s in arm.sections])

    def _rest(self, pressures):
        """Rest curvatures u1*, u2* (rad/m) and stretch v* of every section at ``pressures``."""
        if not self.arm.tubes:
            ns = len(self.arm.sections)
            return np.zeros(ns), np.zeros(ns), np.ones(ns)
        return solver.rest_strains(self.arm, solver.channel_pressures(self.arm, pressures, self.planar))

    def _shape(self, converged: bool = True) -> ShapeEstimate:
        dim = self._pos.shape[1]
        backbone = np.empty((self.n_samples, dim))
        hermite_resample(self._s, self._pos, self._tan, self.s_query, backbone)
        backbone[-1] = self._ends[-1, :dim]
        return ShapeEstimate(tip=self._ends[-1, :dim], section_ends=self._ends, backbone=backbone,
                             section_frames=self._frames, converged=converged)


class LoadCellShape(_Integrating):
    """Integrate the full equilibrium equations from the measured base wrench (§4.2.1).

    Initial conditions (Eqs. 4.1–4.2): base inclinometer θ0 and load-cell (n0, m0); the
    nominal arm's weight per length and endplates give n(s) = n0 − ∫q (an unknown tip payload
    is in n0: nothing else about it is needed); rest strains from the commanded pressures.
    The tip boundary condition is not used, so with exact readings the estimate is the
    solver's equilibrium up to discretisation, and sensor errors propagate as Eq. (4.12)
    says. Spatial: the 6-axis wrench, and the base frame from the base tilt (elevation of d3)
    with the mounting's heading (d2 = +z).

    An initial-value integration does not enjoy the tip condition's correction, so its RK4
    error is ~100× the solver's at equal steps (OctArm VI: 8e-5 m at 16 steps per section,
    3e-7 m at 64): the default is 64 steps per section.

    Options:
        steps_per_section: RK4 steps per section (default 64).
    """

    name = "load_cell"

    def __init__(self, arm, planar, scene, n_samples, steps_per_section: int = 64):
        super().__init__(arm, planar, scene, n_samples, steps_per_section)
        g = np.array([0.0, -scene.gravity, 0.0])[: 2 if planar else 3]
        self.q = self.mass_per_length[:, None] * g[None, :]
        self.point = self.endplate[:, None] * g[None, :]
        self.c_a = np.array([1.0 / s.EA for s in arm.sections])
        self.c_g = np.array([1.0 / s.GA for s in arm.sections])
        self.c_j = np.array([1.0 / s.GJ for s in arm.sections])
        self._work = np.zeros((8, NSTATE)) if not planar else np.zeros((7, 6))
        self._quat0 = np.empty(4)

    def _estimate(self, readings, pressures, truth):
        u1_rest, u2_rest, v_rest = self._rest(pressures)
        if self.planar:
            n0x, n0y, m0 = readings.base_wrench
            load_cell_planar(float(readings.inclinometers[0]), n0x, n0y, m0, self.sec_len,
                             self.sec_steps, self.c_a, self.c_g, self.c_i, u2_rest, v_rest, self.q,
                             self.point, self._work, self._s, self._pos, self._tan, self._ends)
        else:
            # The base tilt (elevation of d3) with the known mounting heading (d2 = +z).
            rotation_to_quaternion(base_rotation(float(readings.inclinometers[0, 0])),
                                   self._quat0)
            load_cell_spatial(self._quat0, readings.base_wrench[:3], readings.base_wrench[3:], self.sec_len,
                              self.sec_steps, self.c_a, self.c_g, self.c_i, self.c_j, u1_rest,
                              u2_rest, v_rest, self.q, self.point, self._work, self._s, self._pos,
                              self._tan, self._ends, self._frames)
        return self._shape()


class _ReducedModel(_Integrating):
    """The reduced model of §4.2.2–4.2.3 (Eq. 4.17), solved as a boundary-value problem.

    Assumptions (the thesis's): each section stretches only by pressurisation, uniformly
    (stretch v_i); the backbone is unshearable (r' = v·d3); the axial force is neglected, so
    the shear force only carries the weight: planar n1' = w·cos θ (i.e. −q·d1), m' = −v·n1,
    θ' = u* + m/EI, which eliminates to θ''' = −(v/EI)·w·cos θ. Unknowns: the base moment and
    the shear force at the start of every section (it may jump at a junction, as each
    section's third boundary condition in the thesis leaves it free); θ and m are continuous
    (Eqs. 4.35–4.39) and the tip is moment-free (Eq. 4.33/4.40). The boundary data of the
    subclass close the system. Solved by damped Newton on the RK4 shooting map (the thesis
    used bvp4c), warm-started from the previous estimate until :meth:`reset`.

    Spatial: body shear (n1, n2) per section with (n1, n2)' = −(Rᵀq)₁,₂ ± u3·(n2, n1),
    m' = −v·d3 × n, u = u* + C⁻¹Rᵀm (torsion kept); unknowns m0 (3) and (n1, n2) per
    section; data two numbers per section (cable encoders ∫u1, ∫u2; IMUs the section-end
    axis d3) and m(L) = 0.

    Options:
        steps_per_section: RK4 steps per section (default: the solver's 16).
        tol: boundary-residual tolerance (rad). max_iter: Newton iterations.
    """

    def __init__(self, arm, planar, scene, n_samples, steps_per_section: int | None = None,
                 tol: float = 1e-10, max_iter: int = 60):
        super().__init__(arm, planar, scene, n_samples, steps_per_section)
        if not (tol > 0 and int(max_iter) == max_iter and max_iter >= 1):
            raise ValueError(f"tol must be > 0 and max_iter an integer >= 1; got {tol!r}, {max_iter!r}")
        self.tol = float(tol)
        self.max_iter = int(max_iter)
        ns = len(arm.sections)
        self.weight = self.mass_per_length * scene.gravity
        self.q = self.mass_per_length[:, None] * np.array([0.0, -scene.gravity, 0.0])[None, :]
        self.c_j = np.array([1.0 / s.GJ for s in arm.sections])
        ei_max = 1.0 / self.c_i.min()
        self.moment_scale = arm.length / ei_max
        self.force_scale = arm.length**2 / ei_max
        n_moment, n_shear = (1, 1) if planar else (3, 2)
        self.unknown_scale = np.array([ei_max / arm.length] * n_moment
                                      + [ei_max / arm.length**2] * (n_shear * ns))
        self._z = np.zeros(self.unknown_scale.size)
        self._res = np.empty(self._z.size)
        # The spatial Newton's Jacobian, kept between estimates (see reduced_spatial_newton).
        self._jac = np.empty((self._z.size, self._z.size))
        self._jac_ok = np.zeros(1, dtype=np.bool_)
        self._curv = np.empty((ns, 2))
        self._kernel_work = np.zeros((6, REDUCED_STATE))
        self.tip_weight = 0.0

    def reset(self) -> None:
        self._z[:] = 0.0
        self._jac_ok[0] = False

    def _boundary_data(self, readings, v_rest):
        """(stretch (ns,), targets: planar section-end θ (ns,), spatial as
        :meth:`_spatial_misfit` takes them, number of planar θ targets used)."""
        raise NotImplementedError

    def _base_frame(self, readings) -> np.ndarray:
        """Spatial: the base directors (3, 3) the readings give (the base tilt sensor's
        elevation of d3, the mount's heading)."""
        return base_rotation(float(readings.inclinometers[0, 0]))

    LEFT_OUT_LIMIT = math.inf
    """Largest :meth:`_left_out_misfit` of a root taken without trying the other starts."""
    SPATIAL_STARTS = (None, "zero", "model")
    """Newton's starts in space, in order: the previous estimate, the unloaded guess, the
    nominal model's equilibrium."""

    def _left_out_misfit(self, model, data) -> float:
        """Spatial: how far the converged root is from data the fit does not use (0: none):
        the reduced model can have several roots, and this picks among them."""
        return 0.0

    def _spatial_data(self, target) -> tuple:
        """Spatial: the data argument of :func:`reduced_spatial_residual`; here the
        sections' integrated curvatures (∫u1, ∫u2), ``target`` (ns, 2)."""
        return CABLE_DATA, np.ascontiguousarray(target, dtype=float), np.zeros((len(self.sec_len), 3, 3))

    def _estimate(self, readings, pressures, truth):
        u1_rest, u2_rest, v_rest = self._rest(pressures)
        stretch, target, n_angles = self._boundary_data(readings, v_rest)
        if self.planar:
            theta0 = float(readings.inclinometers[0])
            fixed = (theta0, self.sec_len, self.sec_steps, self.c_i, u2_rest, stretch, self.weight, target,
                     n_angles, self.tip_weight, self.moment_scale, self.force_scale, self._ends)

            def residual(z):
                reduced_residual(z, *fixed, self._res)
                return self._res.copy()
        else:
            rot0 = self._base_frame(readings)
            ns = len(self.sec_len)
            model = (rot0, self.sec_len, self.sec_steps, self.c_i, self.c_j, u1_rest, u2_rest,
                     np.asarray(stretch, dtype=float), self.q, self._kernel_work, self._s, self._pos,
                     self._tan, self._ends, self._frames, self._curv, self.moment_scale)
            data = self._spatial_data(target)
        ok = False
        best = None  # (misfit of the data the fit leaves out, unknowns) of the best converged root
        seeds = (None, "zero") if self.planar else self.SPATIAL_STARTS
        for seed in seeds:
            if seed == "zero":
                self._z[:] = 0.0  # the warm start led astray: retry from the unloaded guess
            elif seed == "model":
                self._z[:] = self._model_seed(pressures)
            if self.planar:
                ok, _ = damped_newton(residual, self._z, self.unknown_scale, self.tol, self.max_iter)
            else:
                self._jac_ok[0] &= seed is None  # a new start: a new Jacobian
                ok, _ = reduced_spatial_newton(self._z, self.unknown_scale, self.tol, self.max_iter,
                                               20.0, model, data, self._jac, self._jac_ok)
            if ok:
                left_out = 0.0 if self.planar else self._left_out_misfit(model, data)
                if best is None or left_out < best[0]:
                    best = (left_out, self._z.copy())
                if left_out <= self.LEFT_OUT_LIMIT:
                    break
        ok = best is not None
        if ok:
            self._z[:] = best[1]
        if not np.all(np.isfinite(self._z)):
            self._z[:] = 0.0
        if self.planar:
            reduced_planar(theta0, self._z[0], self._z[1:], self.sec_len, self.sec_steps, self.c_i,
                           u2_rest, stretch, self.weight, True, self._s, self._pos, self._tan, self._ends)
        else:
            reduced_spatial(rot0, self._z[:3], self._z[3:].reshape(ns, 2), self.sec_len, self.sec_steps,
                            self.c_i, self.c_j, u1_rest, u2_rest, stretch, self.q, True,
                            self._kernel_work, self._s, self._pos, self._tan, self._ends,
                            self._frames, self._curv)
        return self._shape(converged=bool(ok))


    def _model_seed(self, pressures) -> np.ndarray:
        """Spatial unknowns (m0, (n1, n2) at every section start) of the nominal model's
        equilibrium at ``pressures``: a start for Newton near the measured state when the
        previous estimate and the unloaded guess both fail (curled spatial arms)."""
        eq = solver.solve(self.arm, pressures, self.scene, planar=False)
        rows = [0, *eq.section_ends[:-1]]
        body = np.einsum("kji,kj->ki", eq.orientations[rows], eq.internal_force[rows])
        return np.concatenate([eq.base_moment, body[:, :2].ravel()])


class CableEncoderShape(_ReducedModel):
    """Cable encoders + base inclinometer (§4.2.2): Eq. 4.17 with boundary data 4.31–4.33.

    Per section the cables give the stretch v_i (Eq. 4.27) and the turning Δθ_i (Eq. 4.30;
    spatially ∫u1, ∫u2): see :func:`cable_section_strains`. Planar: θ(s_i) = θ0 + Σ Δθ fixes
    the section-end angles. Independent of an unknown tip payload, up to the neglected axial
    force; exact when no force acts along the arm.
    """

    name = "cable_encoder"

    def __init__(self, arm, planar, scene, n_samples, **options):
        super().__init__(arm, planar, scene, n_samples, **options)
        self.radius = cable_radius(arm)

    def _boundary_data(self, readings, v_rest):
        stretch, turning = cable_section_strains(readings, self.sec_len, self.radius)
        if not self.planar:
            return stretch, turning, 0
        return stretch, float(readings.inclinometers[0]) + np.cumsum(turning), len(self.sec_len)


class InclinometerShape(_ReducedModel):
    """Inclinometers at the base and every section end (§4.2.3, Eqs. 4.34–4.41); in space,
    IMUs in their place.

    Stretch from the actuator model at the commanded pressures. Without ``known_payload_kg``
    all n_sections + 1 inclinometers are used (the payload may be unknown); with it, the tip
    inclinometer is not needed: the tip shear n1(L) = −W·cos θ(L) (Eq. 4.41; W the known
    payload plus tip endplate weight) replaces it (planar only).

    Spatial: a tilt sensor cannot see heading, so the sensors are IMUs
    (:class:`~softarm_gym.sensing.sensors.SensorReadings` ``imu``): the base IMU gives the
    base frame and each section-end IMU its axis d3, matched by the reduced model through
    the two angles of the estimated d3 off the measured one (atan2 of its components along the
    measured d1 and d2 over the one along d3), with m(L) = 0.

    Options:
        known_payload_kg: the tip payload, if known (kg); ``None``: unknown (planar only).
    """

    name = "inclinometer"

    def __init__(self, arm, planar, scene, n_samples, known_payload_kg: float | None = None,
                 **options):
        if not planar and known_payload_kg is not None:
            raise ValueError("known_payload_kg applies to the planar inclinometer estimator only")
        super().__init__(arm, planar, scene, n_samples, **options)
        if known_payload_kg is not None:
            bad = isinstance(known_payload_kg, bool) or not isinstance(known_payload_kg, (int, float))
            if bad or not np.isfinite(known_payload_kg) or known_payload_kg < 0:
                raise ValueError(f"known_payload_kg must be a finite number >= 0 or None; got "
                                 f"{known_payload_kg!r}")
            self.tip_weight = (float(known_payload_kg) + self.endplate[-1]) * scene.gravity
        self.known_payload_kg = known_payload_kg

    def _boundary_data(self, readings, v_rest):
        ns = len(self.sec_len)
        if not self.planar:
            return v_rest, self._imu(readings)[1:], 0
        n_angles = ns if self.known_payload_kg is None else ns - 1
        return v_rest, np.asarray(readings.inclinometers[1:], dtype=float), n_angles

    def _imu(self, readings) -> np.ndarray:
        """The IMU frames (ns + 1, 3, 3) of spatial readings."""
        if readings.imu.shape[0] != len(self.sec_len) + 1:
            raise ValueError("the spatial inclinometer estimator reads IMUs: readings.imu must "
                             f"hold {len(self.sec_len) + 1} sensors (synthesize() of a spatial "
                             f"equilibrium); got {readings.imu.shape[0]}")
        return imu_frames(readings.imu)

    def _base_frame(self, readings) -> np.ndarray:
        return self._imu(readings)[0]

    def _spatial_data(self, target) -> tuple:
        # The estimated end axes d3 against the measured frames (ns, 3, 3).
        return IMU_DATA, np.zeros((len(self.sec_len), 2)), np.ascontiguousarray(target, dtype=float)

    SPATIAL_STARTS = (None, "model", "zero")  # a suspect root is re-solved near the model's
    LEFT_OUT_LIMIT = math.radians(15.0)
    """A root whose section twists are more than this off the IMUs' is suspect: on random
    spatial OctArm V steps right roots stay within 5° (p95; 2.5° sensors would add theirs),
    wrong ones (other roots matching the same axes) are 19–180° off."""

    def _left_out_misfit(self, model, data) -> float:
        # The fit matches each end axis d3; the IMU also measures the twist about it (d1).
        reduced_spatial_residual(self._z, model, data, np.empty(self._z.size))
        measured = data[2]
        d1 = self._frames[:, :, 0]
        twist = np.arctan2(np.einsum("ki,ki->k", d1, measured[:, :, 1]),
                           np.einsum("ki,ki->k", d1, measured[:, :, 0]))
        return float(np.abs(twist).max())


_CLASSES = {"true": TrueShape, "model": ModelShape, "constant_curvature": ConstantCurvatureShape,
            "cable_encoder": CableEncoderShape, "inclinometer": InclinometerShape,
            "load_cell": LoadCellShape}


def make_estimator(name: str, arm: solver.designs.ArmDesign, planar: bool = True,
                   scene: solver.Scene | None = None, n_samples: int = DEFAULT_SAMPLES,
                   **options) -> Estimator:
    """Build a shape estimator.

    Args:
        name: one of :data:`ESTIMATORS`.
        arm: the nominal design (the estimator's knowledge of the arm).
        planar: planar or spatial estimation.
        scene: the known mounting: base angle and gravity are used; payload and tip loads
            are not known to any estimator (default: hanging, 9.81 m/s²).
        n_samples: K, number of backbone samples in every :class:`ShapeEstimate` (>= 2).
        **options: estimator-specific options (see each class).

    Raises:
        ValueError: unknown name, bad arguments, or unknown options.
    """
    if name not in ESTIMATORS:
        raise ValueError(f"unknown estimator {name!r}; choose one of {', '.join(ESTIMATORS)}")
    if not isinstance(arm, solver.designs.ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")
    scene = solver.Scene() if scene is None else scene
    if not isinstance(scene, solver.Scene):
        raise ValueError(f"scene must be a solver.Scene; got {type(scene).__name__}")
    if isinstance(n_samples, bool) or int(n_samples) != n_samples or n_samples < 2:
        raise ValueError(f"n_samples must be an integer >= 2; got {n_samples!r}")
    if planar and not arm.planar_channels and arm.tubes:
        raise ValueError(f"design {arm.name!r} defines no planar channels; use planar=False")
    try:
        return _CLASSES[name](arm, planar, scene, int(n_samples), **options)
    except TypeError as exc:
        raise ValueError(f"bad options for the {name!r} estimator: {exc}") from None
