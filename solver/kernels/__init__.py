"""The solver's numba kernels (internal: only :mod:`solver` and its tests import them).

Module-level ``@njit(cache=True)`` functions (:mod:`solver.jit`) and the constants they freeze:

* :mod:`~solver.kernels.planar`: planar single shooting — path following, fold scan,
  stepper and batch kernels (docs/design.md §6–8);
* :mod:`~solver.kernels.spatial`: spatial single shooting and its stability test (§9);
* :mod:`~solver.kernels.spatial_shooting`: spatial multiple shooting;
* :mod:`~solver.kernels.contact`, :mod:`~solver.kernels.spatial_contact`: multiple shooting
  with penalty contact, planar and spatial (§10);
* :mod:`~solver.kernels.self_contact`: the arm against itself;
* :mod:`~solver.kernels.obstacles`: obstacle geometry and contact laws;
* :mod:`~solver.kernels.relax`: energy relaxation of a snapped contact state;
* :mod:`~solver.kernels.homotopy`: the continuation's step control;
* :mod:`~solver.kernels.grid`: the RK4 grid check (§11).

Rules (``tests/test_architecture.py``): a kernel module never imports :mod:`solver.paths`;
nothing outside :mod:`solver` imports this package. Names other modules use are plain (the
package already says they are internal); an underscored name stays in its module.
"""
