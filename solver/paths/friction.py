"""The tangential state of frictional contact on the contact paths: the friction samples a
level carries (``layout.L_MU``, ``layout.L_FRICTION``, and a planar level's self-contact
samples ``layout.L_SELF_FRICTION``), where a solve's come from (a cold
start, a warm start on the same or another contact layout) and what a result keeps of them
(docs/design.md §9)."""

from __future__ import annotations

import numpy as np

from solver import layout as L
from solver.kernels.contact import NEAR_SUBSTEPS
from solver.kernels.self_contact import SUBPOINTS
from solver.results import Equilibrium

# Samples per RK4 step: the nodes of its refinement near an obstacle.
NODES = NEAR_SUBSTEPS + 1


def new_level(a: tuple) -> tuple:
    """Scratch arrays shaped like the level tuple ``a`` (planar or spatial) for a path to
    fill, with copies of its tangential state (``layout.L_MU`` on), which a path carries."""
    return (*(np.empty_like(x) for x in a[:L.L_MU]), *(x.copy() for x in a[L.L_MU:]))


def new_samples(rows: int, n_obstacles: int) -> np.ndarray:
    """Friction samples (rows, NODES, n_obstacles, N_FS) with no tangential state: no anchor
    (NaN), no impulse, slip or work."""
    return _released(np.zeros((rows, NODES, n_obstacles, L.N_FS)))


def no_samples(n_obstacles: int) -> np.ndarray:
    """The friction samples of a level without friction: no rows (the kernels skip it)."""
    return np.zeros((0, NODES, n_obstacles, L.N_FS))


def landed(level: tuple) -> tuple:
    """``level`` with no tangential state: where the arm snaps (a dynamic event), it lands
    without the anchors it had, and they form again where it comes to rest."""
    return (*level[:L.L_FRICTION], *(_released(fs) for fs in level[L.L_FRICTION:]))


def _released(samples: np.ndarray) -> np.ndarray:
    """Friction samples of ``samples``' shape with no tangential state (none without rows)."""
    if not samples.shape[0]:
        return samples
    fs = np.zeros(samples.shape)
    for c in (L.FS_A, L.FS_NEW, L.FS_R):
        fs[..., c:c + 3] = np.nan
    return fs


def start_self_samples(scene, segs, warm_start: Equilibrium | None) -> np.ndarray:
    """The self-contact friction samples (M, c + 1, SUBPOINTS, N_FS; ``layout.L_SELF_FRICTION``)
    a planar contact solve of ``scene`` on the segment table ``segs`` (M segments, the
    longest of c steps) starts from: no rows without self-contact friction; else the warm
    start's anchors where it was solved on the same segments, none elsewhere (a cold start,
    another contact layout: anchors form again at the first accepted state)."""
    rows = segs.shape[0] if scene.self_friction > 0.0 else 0
    shape = (rows, int(segs[:, L.SEG_STEPS].max()) + 1 if rows else 0, SUBPOINTS, L.N_FS)
    fs = _released(np.zeros(shape))
    old = warm_start.self_friction_samples if warm_start is not None else None
    if rows and old is not None and old.shape == fs.shape:
        fs[..., L.FS_A:L.FS_A + 3] = old[..., L.FS_A:L.FS_A + 3]
    return fs


def layout_arcs(layout, sec_start) -> np.ndarray:
    """Reference arc length (m) of every record row of a contact ``layout`` (Σ(steps + 1),)."""
    h = layout.sec_len / layout.sec_steps
    return np.concatenate([s0 + np.arange(n + 1) * step
                           for n, step, s0 in zip(layout.sec_steps, h, sec_start)])


def sample_arcs(s: np.ndarray, section_ends) -> np.ndarray:
    """(rows, NODES) reference arc length (m) of every friction sample of a contact record
    whose rows lie at ``s`` (rows,): the nodes of each step's refinement; NaN in the rows of
    section ends, which start no step."""
    s = np.asarray(s, dtype=float)
    nxt = np.append(s[1:], np.nan)
    arcs = s[:, None] + (nxt - s)[:, None] * (np.arange(NODES) / NEAR_SUBSTEPS)[None, :]
    arcs[np.asarray(section_ends, dtype=int)] = np.nan
    return arcs


def start_samples(scene, layout, sec_start, warm_start: Equilibrium | None,
                  moving: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(μ (k,), friction samples) a contact solve on ``layout`` starts from: none (no rows)
    without friction; else the warm start's anchors, resampled in arc length where it was
    solved on another contact layout, for each obstacle it had in the same place (or moved
    there, ``moving``); no anchor elsewhere (a cold start, a new obstacle)."""
    mu = scene.friction_array()
    k = mu.size
    if not scene.has_friction:
        return mu, no_samples(k)
    fs = new_samples(layout.n_rows, k)
    old = warm_start.friction_samples if warm_start is not None else None
    if old is None or old.ndim != 4 or old.shape[0] == 0 or old.shape[2] != k \
            or warm_start.scene is None:
        return mu, fs
    before = warm_start.scene.obstacles
    keep = [d for d in range(k) if len(before) == k and type(before[d]) is type(scene.obstacles[d])
            and (moving or _same_place(before[d], scene.obstacles[d]))]
    if old.shape[:2] == fs.shape[:2]:
        fs[:, :, keep, L.FS_A:L.FS_A + 3] = old[:, :, keep, L.FS_A:L.FS_A + 3]
        return mu, fs
    if not warm_start.s.size or old.shape[0] != warm_start.s.size:
        return mu, fs
    src = sample_arcs(warm_start.s, warm_start.section_ends).ravel()
    dst = sample_arcs(layout_arcs(layout, sec_start), layout.section_ends)
    order = np.flatnonzero(np.isfinite(src))
    order = order[np.argsort(src[order], kind="stable")]
    for d in keep:
        anchors = old[:, :, d, L.FS_A:L.FS_A + 3].reshape(-1, 3)[order]
        fs[:, :, d, L.FS_A:L.FS_A + 3] = _interpolate(src[order], anchors, dst)
    return mu, fs


def _same_place(a, b) -> bool:
    """Whether two obstacles of one kind stand in the same place (their geometry agrees)."""
    fields = ("center", "point", "axis", "radius")
    return all(getattr(a, f) == getattr(b, f) for f in fields if hasattr(a, f))


def _interpolate(src: np.ndarray, values: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """``values`` (n, 3) at sorted arc lengths ``src`` (n,), linearly at ``dst`` (any shape;
    NaN where it is NaN, outside ``src`` or next to a NaN value)."""
    out = np.full((*dst.shape, 3), np.nan)
    if src.size < 2:
        return out
    flat = dst.ravel()
    j = np.clip(np.searchsorted(src, flat) - 1, 0, src.size - 2)
    inside = np.isfinite(flat) & (flat >= src[0]) & (flat <= src[-1])
    span = src[j + 1] - src[j]
    t = np.where(span > 0.0, (flat - src[j]) / np.where(span > 0.0, span, 1.0), 0.0)
    mixed = values[j] + t[:, None] * (values[j + 1] - values[j])
    mixed[~inside] = np.nan
    out.reshape(-1, 3)[:] = mixed
    return out


def turn_anchors(samples: np.ndarray, obstacle: int, angle: float) -> None:
    """Turn the anchors of ``obstacle`` in ``samples`` (in place) by ``angle`` (rad,
    counter-clockwise about its centre, in the x–y plane): the object they stick to turned."""
    c, s = np.cos(angle), np.sin(angle)
    a = samples[:, :, obstacle, L.FS_A:L.FS_A + 2]
    x, y = a[..., 0].copy(), a[..., 1].copy()
    a[..., 0] = c * x - s * y
    a[..., 1] = s * x + c * y


def friction_fields(samples: np.ndarray, warm_start: Equilibrium | None,
                    self_samples: np.ndarray | None = None) -> dict:
    """The Equilibrium fields of a contact solve whose level ends with the friction
    ``samples`` (and the self-contact ones ``self_samples``): copies of them (none without
    friction), and the energy dissipated along the path to it — the warm start's, and this
    path's, the work its samples recorded."""
    dissipated = warm_start.dissipated if warm_start is not None else 0.0
    fields = {}
    for name, fs in (("friction_samples", samples), ("self_friction_samples", self_samples)):
        if fs is not None and fs.shape[0]:
            fields[name] = fs.copy()
            dissipated += float(fs[..., L.FS_WORK].sum())
    return dict(dissipated=dissipated, **fields)
