"""Input checks that :func:`solver.solve`, :class:`solver.Stepper` and :mod:`solver.grasp` share.

Bad input raises ``ValueError`` with one line naming the problem, before any kernel runs
(docs/design.md §11). :func:`request` turns the arguments of a solve into the validated
:class:`~solver.problem.Problem` the paths take.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.designs import ArmDesign
from solver.jit import njit
from solver.problem import PackedArm, Problem, pack
from solver.results import BatchState, Equilibrium
from solver.scene import Scene, core_distance
from solver.settings import MODELS, Settings

__all__ = ["request", "checked_pressures", "channels_of", "explain_bad_pressures", "check_request",
           "check_warm_start", "batch_inputs", "check_batch_state", "NO_INDEX"]


def request(arm: ArmDesign, pressures, scene: Scene | None, model: str, planar: bool,
            warm_start: Equilibrium | None, settings: Settings) -> Problem:
    """The validated :class:`~solver.problem.Problem` of a solve's arguments (as
    :func:`solver.solve` takes them; ``scene`` None: the default scene).

    Raises:
        ValueError: naming the first bad argument.
    """
    scene = Scene() if scene is None else scene
    check_request(arm, scene, model, planar, settings)
    packed = pack(arm, model, settings)
    p_inputs, p_channel = checked_pressures(arm, pressures, planar, packed)
    if warm_start is not None:
        check_warm_start(warm_start, arm, scene, model, planar)
    return Problem(arm, packed, scene, model, planar, settings, p_inputs, p_channel, warm_start)


def checked_pressures(arm: ArmDesign, pressures, planar: bool,
                      packed: PackedArm) -> tuple[np.ndarray, np.ndarray]:
    """Validate input pressures and expand planar inputs to spatial channels (Pa)."""
    n = arm.n_inputs(planar)
    try:
        # A copy: the result keeps these pressures, so later edits by the caller cannot leak in.
        p = np.array(pressures, dtype=float)
    except (TypeError, ValueError):
        p = None
    if p is None or p.ndim != 1 or p.shape[0] != n:
        names = arm.input_names(planar)
        raise ValueError(
            f"design {arm.name!r} expects {n} pressures in {'planar' if planar else 'spatial'} "
            f"mode ({', '.join(names) or 'none: a passive rod'}); got "
            f"{np.array2string(np.asarray(pressures, dtype=object), max_line_width=10**6)}")
    # Spatial inputs are the channels: only checked (an empty index expands nothing).
    index = packed.spatial_of_planar if planar else NO_INDEX
    p_channel = np.empty(index.shape[0]) if planar else p
    if not channels_of(p, index, arm.max_pressure * (1 + 1e-12), p_channel):
        explain_bad_pressures(arm, p, planar)
    return p, p_channel


NO_INDEX = np.empty(0, dtype=np.int64)


@njit
def channels_of(p, index, p_max, out):
    """Spatial-channel pressures ``out[c] = p[index[c]]`` of planar inputs ``p``; False if an
    input is not finite, negative or above ``p_max`` (then ``out`` is incomplete)."""
    for k in range(p.shape[0]):
        if not (0.0 <= p[k] <= p_max):
            return False
    for c in range(index.shape[0]):
        out[c] = p[index[c]]
    return True


def explain_bad_pressures(arm, p, planar):
    """Raise the ``ValueError`` naming the first bad pressure of ``p`` (n_inputs,): not
    finite, negative or above the rating."""
    names = arm.input_names(planar)
    bad = ~np.isfinite(p)
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(f"pressure for channel {names[k]!r} is not finite: {p[k]}")
    if (p < 0).any():
        k = int(np.argmax(p < 0))
        raise ValueError(f"pressure for channel {names[k]!r} is negative ({p[k]:.6g} Pa); "
                         "channel pressures are gauge pressures >= 0")
    k = int(np.argmax(p > arm.max_pressure))
    raise ValueError(f"pressure for channel {names[k]!r} ({p[k]:.6g} Pa) exceeds the design's "
                     f"rated maximum {arm.max_pressure:.6g} Pa")


def check_request(arm, scene, model, planar, settings):
    """The design, scene, model, mode and settings of a request make sense together."""
    if not isinstance(arm, ArmDesign):
        raise ValueError(f"arm must be a solver.designs.ArmDesign; got {type(arm).__name__}")
    if not isinstance(scene, Scene):
        raise ValueError(f"scene must be a solver.Scene; got {type(scene).__name__}")
    if model not in MODELS:
        raise ValueError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
    if planar and not scene.is_planar:
        raise ValueError("scene has out-of-plane loads (tip_force z or tip_moment x/y) or "
                         "obstacles other than discs (cylinders, spheres); use planar=False")
    if scene.self_contact is not None:
        if not planar:
            raise ValueError("self-contact is supported in planar solves only")
        if model == "constant_curvature":
            raise ValueError("the constant-curvature model has no contact; self-contact needs "
                             "model 'full' or 'unshearable'")
        if not all(arm.half_thickness()):
            raise ValueError(f"self-contact needs every section's half-thickness, from its tubes; "
                             f"design {arm.name!r} has a section no tube spans")
    if planar and not arm.planar_channels and arm.tubes:
        raise ValueError(f"design {arm.name!r} defines no planar channels; use planar=False")
    if not isinstance(settings, Settings):
        raise ValueError(f"settings must be a solver.Settings; got {type(settings).__name__}")


def check_warm_start(warm_start, arm, scene, model, planar):
    """A warm start must be a result of this arm, model and mode, solved in a scene the path
    can ramp from: the same mounting, and no obstacle it was not solved with lying across
    its backbone (loads and pressures ramp; a base or an obstacle cannot)."""
    if not isinstance(warm_start, Equilibrium):
        raise ValueError("warm_start must be an Equilibrium returned by solve()")
    if warm_start.arm is None or warm_start.scene is None:
        raise ValueError("warm_start does not say which arm and scene it was solved for; pass "
                         "an Equilibrium returned by solve() or a Stepper")
    if warm_start.arm is not arm and warm_start.arm != arm:
        raise ValueError(f"warm_start was solved for design {warm_start.arm.name!r}, not for "
                         f"this {arm.name!r} design (or for another variant of it)")
    if warm_start.planar != planar or warm_start.model != model:
        raise ValueError(f"warm_start comes from a {'planar' if warm_start.planar else 'spatial'} "
                         f"{warm_start.model!r} solve, not a {'planar' if planar else 'spatial'} "
                         f"{model!r} one")
    if warm_start.scene.base_angle_deg != scene.base_angle_deg:
        raise ValueError(f"warm_start was solved at a different base angle "
                         f"({warm_start.scene.base_angle_deg:g} deg, not {scene.base_angle_deg:g})")
    if warm_start.scene.obstacles == scene.obstacles:
        # Nothing new (a stepper adopting its own result: every grasp env step), without
        # building the frictionless copies below (two per obstacle: 6 % of a profiled grasp
        # env step).
        return
    # (An obstacle whose friction alone changed is the same obstacle: μ carries no geometry.)
    before = [replace(d, friction=0.0) for d in warm_start.scene.obstacles]
    new = [k for k, d in enumerate(scene.obstacles) if replace(d, friction=0.0) not in before]
    if not new:
        return
    points = warm_start.positions if warm_start.positions.shape[0] else warm_start.tip[None, :]
    for k in new:
        d = scene.obstacles[k]
        if np.min(core_distance(d, points)) < d.radius:
            raise ValueError(f"warm_start's backbone lies inside obstacle {k} ({d}), which it "
                             "was not solved with: an obstacle cannot be ramped in; solve cold")


def batch_inputs(arm, pressures, scene, model, planar, settings):
    """Validated (request at zero pressure, input pressures (n, n_inputs), channel pressures
    (n, n_channels)) for the batch calls (each row's request: :meth:`Problem.with_inputs`)."""
    scene = Scene() if scene is None else scene
    check_request(arm, scene, model, planar, settings)
    packed = pack(arm, model, settings)
    p = np.asarray(pressures, dtype=float)
    if p.ndim != 2 or p.shape[1] != arm.n_inputs(planar):
        raise ValueError(f"pressures must have shape (n, {arm.n_inputs(planar)}); got {p.shape}")
    for row in p[~np.all((p >= 0) & (p <= arm.max_pressure * (1 + 1e-12)), axis=1)][:1]:
        explain_bad_pressures(arm, row, planar)
    if not arm.n_channels:
        channel = np.zeros((p.shape[0], 1))  # the kernels' placeholder of a passive rod
    else:
        channel = p[:, packed.spatial_of_planar] if planar else p
    at_rest = Problem(arm, packed, scene, model, planar, settings, np.zeros(arm.n_inputs(planar)),
                      np.zeros(arm.n_channels))
    return at_rest, p, np.ascontiguousarray(channel)


def check_batch_state(state, arm, scene, n):
    """A step_batch state must come from step_batch with this arm, in this scene (the copies
    are stepped under the same loads), with n copies."""
    if not isinstance(state, BatchState) or state.arm is None:
        raise ValueError("state must be the BatchState a previous step_batch call returned")
    if state.arm is not arm and state.arm != arm:
        raise ValueError(f"state was stepped for design {state.arm.name!r}, not for this "
                         f"{arm.name!r} design (or for another variant of it)")
    if state.scene != scene:
        raise ValueError(f"state was stepped in {state.scene}, not in {scene}: step_batch keeps "
                         "the loads; solve() ramps from one scene to another")
    if state.base_moment.shape != (n,):
        raise ValueError(f"state holds {state.base_moment.shape[0]} arms; pressures has {n} rows")
