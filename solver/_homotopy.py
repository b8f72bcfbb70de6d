"""Shared pieces of the path-following kernels: what a ramp between two load cases is."""

from __future__ import annotations

from solver.jit import njit


@njit
def _big_change(p_a, p_b, loads_a, loads_b):
    """A ramp worth a tangent predictor: new loads, or a pressure moving by > 5 % of the
    largest. Small warm steps (env steps) are predicted well enough by the start state."""
    scale = 0.0
    for c in range(p_a.shape[0]):
        scale = max(scale, abs(p_a[c]), abs(p_b[c]))
    for c in range(p_a.shape[0]):
        if abs(p_b[c] - p_a[c]) > 0.05 * scale:
            return True
    for i in range(loads_a.shape[0]):
        for d in range(loads_a.shape[1]):
            if loads_a[i, d] != loads_b[i, d]:
                return True
    return False
