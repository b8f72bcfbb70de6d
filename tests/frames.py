"""Helpers for checking rendered frames."""

import numpy as np


def colour_mask(frame: np.ndarray, hex_colour: str, tol: int = 30) -> np.ndarray:
    """(H, W) bool: pixels of the (H, W, 3) frame within ``tol`` of ``hex_colour`` per channel."""
    rgb = np.array([int(hex_colour[i:i + 2], 16) for i in (1, 3, 5)])
    return np.all(np.abs(frame.astype(int) - rgb) < tol, axis=2)


def has_colour(frame: np.ndarray, hex_colour: str, tol: int = 30) -> bool:
    """True if some pixel of the (H, W, 3) frame is within ``tol`` of ``hex_colour`` per channel."""
    return bool(np.any(colour_mask(frame, hex_colour, tol)))
