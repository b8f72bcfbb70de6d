"""``far_parts_clear`` (the self-contact guard of contact-free steps) against the plain
definition: every pair of samples farther apart along the arc than the exclusion has a
surface gap above the margin."""

import numpy as np

from solver.kernels.self_contact import far_parts_clear


def _plain(positions, s, half, exclusion, margin):
    for a in range(s.size):
        for b in range(a + 1, s.size):
            if abs(s[b] - s[a]) > exclusion:
                if not np.hypot(*(positions[a] - positions[b])) - half[a] - half[b] > margin:
                    return False
    return True


def test_far_parts_clear_agrees_with_every_pair():
    rng = np.random.default_rng(4)
    verdicts = []
    for _ in range(400):
        n = int(rng.integers(3, 60))
        s = np.linspace(0.0, 0.8, n)
        # A spiral of random tightness: from straight to curled onto itself.
        turn = rng.uniform(0.0, 30.0) * s / 0.8
        theta = np.cumsum(np.concatenate([[0.0], np.diff(s) * turn[1:]]))
        positions = np.column_stack([np.cumsum(np.cos(theta)), np.cumsum(np.sin(theta))]) * (0.8 / n)
        half = rng.uniform(0.01, 0.04, n)
        exclusion, margin = rng.uniform(0.05, 0.2), rng.uniform(0.0, 0.02)
        expect = _plain(positions, s, half, exclusion, margin)
        assert far_parts_clear(positions, s, half, exclusion, margin) == expect
        verdicts.append(expect)
    assert 40 < sum(verdicts) < 360  # both verdicts are exercised
