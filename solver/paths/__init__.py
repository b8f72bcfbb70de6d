"""The solver's Python drivers (internal: only :mod:`solver` and its tests import them).

Each path takes one :class:`solver.problem.Problem` (the arm, its packed arrays, the scene and
its context, model, mode, settings and inputs) and runs the kernels of :mod:`solver.kernels`:

* :mod:`~solver.paths.dispatch`: the path a scene needs;
* :mod:`~solver.paths.planar`: closed-form arcs, planar single shooting, the single/multiple
  choice (docs/design.md §6–8);
* :mod:`~solver.paths.shooting`: planar multiple shooting, with contact (§10);
* :mod:`~solver.paths.spatial`: spatial single and multiple shooting, the in-plane shortcut (§9);
* :mod:`~solver.paths.contact`, :mod:`~solver.paths.spatial_contact`: obstacles, planar and
  spatial;
* :mod:`~solver.paths.grid`: a result's grid check and the next grid (§11).

Rules (``tests/test_architecture.py``): :mod:`solver.kernels` never imports this package;
nothing outside :mod:`solver` imports it. Names other modules use are plain.
"""
