"""Solver settings, the model names and the solver's error."""

from __future__ import annotations

from dataclasses import dataclass, replace

__all__ = ["MODELS", "Settings", "SolverError", "DEFAULT_SETTINGS"]

MODELS = ("full", "unshearable", "constant_curvature")

# Smallest continuation step of :meth:`Settings.finer` (fraction of the ramp).
FINER_DT_MIN = 1.0 / 4096.0


class SolverError(RuntimeError):
    """Raised by ``solve(..., strict=True)`` when no converged equilibrium was found."""


@dataclass(frozen=True)
class Settings:
    """Numerical settings of the shooting solver.

    Attributes:
        steps_per_section: RK4 steps per section (error ∝ steps⁻⁴): the grid every solve
            starts on, and the one its samples are returned on.
        max_refinement: how far a solve may refine that grid where the step-size check
            fails (a power of two: up to ``max_refinement·steps_per_section`` steps in a
            section; 1 never refines). A result the finest allowed grid cannot resolve is
            unconverged (docs/design.md §11).
        tol: Newton tolerance on the moment residuals, relative to the arm's moment scale
            (Σ L_i/EI_i)⁻¹ (in 3D with torsion: L_i/min(EI_i, GJ_i)), or to the loads'
            moment N·L where that is larger (round-off grows with it).
        max_iter: Newton iterations per continuation step.
        dt0, dt_min: first and smallest continuation step (fraction of the ramp).
        contact_dt_min: smallest continuation step of solves with obstacles: a stiff
            penalty makes contact paths turn sharply, and the step that may not tunnel
            through a disc is short where the backbone sweeps past one.
        n_scan: grid points of the fold scan over the base moment (0: no scan).
        gap_tol: deepest penetration (m) a rigid obstacle (``Disc(stiffness=math.inf)``) may
            be left with: its penalty is stiffened tenfold until the solve meets it (up to
            ``RIGID_MAX_STIFFNESS``; 1e-7 m is reachable for OctArm-sized arms).
        shortcuts: skip what a scene does not need (closed-form arcs when unloaded, the
            planar kernel for in-plane spatial solves). False forces the general path; the
            tests use it to check that each shortcut agrees with it.
    """

    steps_per_section: int = 16
    max_refinement: int = 64
    tol: float = 1e-10
    max_iter: int = 12
    dt0: float = 1.0
    dt_min: float = 1.0 / 256.0
    contact_dt_min: float = 1.0 / 16384.0
    n_scan: int = 96
    gap_tol: float = 1e-4
    shortcuts: bool = True

    def __post_init__(self):
        if int(self.steps_per_section) != self.steps_per_section or self.steps_per_section < 1:
            raise ValueError(f"steps_per_section must be an integer >= 1; got {self.steps_per_section}")
        k = self.max_refinement
        if isinstance(k, bool) or int(k) != k or k < 1 or int(k) & (int(k) - 1):
            raise ValueError(f"max_refinement must be a power of two >= 1; got {k}")
        if not (self.tol > 0 and self.max_iter >= 1 and 0 < self.dt_min <= self.dt0 <= 1
                and 0 < self.contact_dt_min <= self.dt0 and 0 < self.gap_tol
                and (self.n_scan == 0 or self.n_scan >= 4)):
            raise ValueError(f"invalid solver settings: {self}")

    @classmethod
    def without_fallback(cls, **kwargs) -> Settings:
        """Plain Newton from the start state: no continuation, no step halving, no fold scan.

        The stress test compares this against the default to show what the fallbacks buy.
        """
        return cls(dt0=1.0, dt_min=1.0, contact_dt_min=1.0, n_scan=0, **kwargs)

    def finer(self) -> Settings:
        """The last fallback of a dead-load solve that found no stable equilibrium: 16× smaller
        continuation steps, more Newton iterations per step and a 4× denser fold scan.

        A path that turns sharply near a fold (an upright arm buckling under a payload, an
        arm near lock-up) makes the default steps jump onto the unstable branch or past the
        fold's end; these settings follow it. They cost several times a default solve, so
        they run only where both shooting methods have failed.
        """
        return replace(self, dt_min=min(self.dt_min, FINER_DT_MIN), max_iter=max(self.max_iter, 40),
                       n_scan=max(self.n_scan, 384))

DEFAULT_SETTINGS = Settings()
