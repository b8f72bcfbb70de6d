"""Helpers for checking rendered frames."""

import numpy as np


def has_colour(frame: np.ndarray, hex_colour: str, tol: int = 30) -> bool:
    """True if some pixel of the (H, W, 3) frame is within ``tol`` of ``hex_colour`` per channel."""
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    return bool(np.any(np.all(np.abs(frame.astype(int) - rgb) < tol, axis=2)))
