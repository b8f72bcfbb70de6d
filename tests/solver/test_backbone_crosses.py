"""``backbone_crosses`` (the self-contact check of a snap's landing, docs/design.md §9.1)
against curves whose self-intersections are known in closed form: the trochoid
x = t − a·sin t, y = −a·cos t loops through itself once a turn for a > 1 (prolate) and
never for a < 1 (curtate), and a circle's arc crosses itself only past a full turn when its
radius shrinks (a spiral never does)."""

import numpy as np
import pytest

from solver.kernels.self_contact import backbone_crosses


def _polyline(x, y):
    positions = np.ascontiguousarray(np.column_stack([x, y]))
    s = np.r_[0.0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))]
    return positions, s


def _trochoid(a, turns, n):
    t = np.linspace(-np.pi, np.pi * (2.0 * turns - 1.0), n)
    return _polyline(t - a * np.sin(t), -a * np.cos(t))


@pytest.mark.parametrize("n", [40, 200])
def test_a_prolate_trochoid_crosses_itself_and_a_curtate_one_does_not(n):
    # one turn from t = −π to π: the loop about t = 0 closes where x(t) = x(−t), i.e. at
    # t = a sin t, which has a root in (0, π) for a > 1 only
    assert backbone_crosses(*_trochoid(2.0, 1.0, n))
    assert not backbone_crosses(*_trochoid(0.5, 1.0, n))
    assert not backbone_crosses(*_trochoid(0.99, 3.0, n))


def test_repeated_samples_and_touching_neighbours_are_not_crossings():
    # a section's end sample repeated (the contact record's rows), at a sharp corner
    positions, s = _trochoid(0.5, 2.0, 60)
    positions = np.ascontiguousarray(np.insert(positions, [20, 40], positions[[20, 40]], axis=0))
    s = np.insert(s, [20, 40], s[[20, 40]])
    assert not backbone_crosses(positions, s)
    corner, s = _polyline(np.array([0.0, 1.0, 1.0, 1.0, 0.0]), np.array([0.0, 0.0, 0.0, 1e-3, 1e-3]))
    assert not backbone_crosses(corner, s)


def test_a_spiral_does_not_cross_and_a_loop_past_a_full_turn_does():
    t = np.linspace(0.0, 4.0 * np.pi, 400)
    r = 1.0 - 0.05 * t  # a tight spiral: two turns, each inside the last
    assert not backbone_crosses(*_polyline(r * np.cos(t), r * np.sin(t)))
    # a curl past a full turn whose end is led straight out across the turns below it
    t = np.linspace(0.0, 2.5 * np.pi, 300)
    r = 1.0 - 0.05 * t
    x, y = r * np.cos(t), r * np.sin(t)
    x = np.r_[x, np.linspace(x[-1], x[-1], 5)]
    y = np.r_[y, np.linspace(y[-1], -2.0, 5)]
    assert backbone_crosses(*_polyline(x, y))
