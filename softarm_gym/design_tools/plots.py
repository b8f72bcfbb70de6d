"""Plots of design sweeps in the manner of thesis Figs. 3.4–3.7 and B.1–B.6."""

from __future__ import annotations

from softarm_gym.plotting import figure, save

__all__ = ["plot_sweeps"]

_STYLES = ("-", "--", "-.", ":")


def plot_sweeps(sweeps, path):
    """Load capacity of the best layout of each sweep, saved to ``path`` (PNG).

    Sweeps over several sizes give load capacity versus length (Figs. 3.4–3.5, B.1–B.6),
    one curve per sweep, with the best layout written where it changes. Sweeps at a single
    size give load capacity and tube thickness versus the number of sections (Fig. 3.6)
    or versus Young's modulus (Fig. 3.7).

    Args:
        sweeps: :class:`~softarm_gym.design_tools.sweep.Sweep` objects.
        path: output file.

    Returns:
        The (closed) matplotlib figure.
    """
    if not sweeps:
        raise ValueError("nothing to plot: no sweeps")
    if any(len(s.sizes) > 1 for s in sweeps):
        return _versus_size(sweeps, path)
    return _versus_parameter(sweeps, path)


def _versus_size(sweeps, path) -> None:
    fig, ax = figure(figsize=(7, 4.5))
    top = 0.0
    curves = [[(c.length_m if s.constraint != "gripping-radius" else size, c)
               for size, c in zip(s.sizes, s.best_per_size) if c is not None] for s in sweeps]
    at_x: dict = {}  # every curve's W at each x: the top curve labels above, the others below, in order
    for pts in curves:
        for xi, c in pts:
            at_x.setdefault(round(xi, 9), []).append(c.load_n)
    for k, (s, pts) in enumerate(zip(sweeps, curves)):
        if not pts:
            continue
        x = [p[0] for p in pts]
        y = [p[1].load_n for p in pts]
        top = max(top, max(y))
        label = f"{s.n_sections} sections"
        if len({t.params.youngs_modulus for t in sweeps}) > 1:
            label += f", E = {s.params.youngs_modulus / 1e6:.3g} MPa"
        ax.plot(x, y, _STYLES[k % len(_STYLES)], color="k", lw=1.2, label=label)
        previous, last_x = None, -float("inf")
        span = max(x) - min(x) if len(x) > 1 else 1.0
        for xi, (_, c) in zip(x, pts):
            # Label where the best layout changes and the arm lifts, at most one label per
            # 12 % of the curve's span (the short, crowded start keeps only its first layout).
            if c.tubes != previous and c.load_n >= 0 and xi - last_x >= 0.12 * span:
                ax.plot([xi], [c.load_n], "o", color="k", ms=3)
                rank = sorted(at_x[round(xi, 9)], reverse=True).index(c.load_n)
                ax.annotate("-".join(map(str, c.tubes)), (xi, c.load_n), fontsize=7,
                            textcoords="offset points", xytext=(4, 5 if rank == 0 else 5 - 11 * rank - 8),
                            bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
                last_x = xi
            previous = c.tubes
    ax.axhline(0.0, color="0.6", lw=0.8)
    if top > 0:  # like Figs. 3.4-3.5: show where W > 0, and only the start of the fall below
        ax.set_ylim(-0.25 * top, 1.1 * top)
    first = sweeps[0]
    ax.set_xlabel("last section length L_N (m)" if first.constraint == "gripping-radius"
                  else "arm length L (m)")
    ax.set_ylabel("load capacity W at the test pressure p_test (N)")
    ax.set_title(f"{first.fluid} arms, {first.constraint} constraint\n(layouts sized by the shape template "
                 f"at p_{first.template_pressure}; labels: best tube layout, base to tip)", fontsize=10)
    ax.legend(fontsize=8)
    return save(fig, path)


def _versus_parameter(sweeps, path) -> None:
    by_modulus = len({s.params.youngs_modulus for s in sweeps}) > 1
    rows = [(s.params.youngs_modulus / 1e6 if by_modulus else s.n_sections, s.best) for s in sweeps]
    rows = [r for r in rows if r[1] is not None]
    if not rows:
        raise ValueError("nothing to plot: no feasible layout in any sweep")
    x = [r[0] for r in rows]
    fig, ax = figure(figsize=(6.5, 4.2))
    ax.plot(x, [r[1].load_n for r in rows], "k^--", label="load capacity")
    ax.set_xlabel("Young's modulus E (MPa)" if by_modulus else "number of sections N (–)")
    ax.set_ylabel("load capacity W at the test pressure p_test (N)")
    twin = ax.twinx()
    twin.plot(x, [r[1].thickness_m * 1e3 for r in rows], "ko-", mfc="none", label="tube thickness")
    twin.set_ylabel("tube thickness t (mm)")
    if by_modulus:
        ax.set_xscale("log")  # the moduli double from one point to the next
        ax.set_xticks(x, [f"{v:g}" for v in x])
        ax.minorticks_off()
    for xi, (_, c) in zip(x, rows):
        ax.annotate("-".join(map(str, c.tubes)), (xi, c.load_n), fontsize=7,
                    textcoords="offset points", xytext=(-4, 6), ha="right",
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8})
    first = sweeps[0]
    ax.set_title(f"{first.fluid}, {first.constraint}, L = {first.sizes[0]:g} m")
    fig.legend(loc="outside lower center", ncols=2, fontsize=8)
    return save(fig, path)
