"""The memo a design keeps of what the solver derived from it."""

from __future__ import annotations


class DesignCache:
    """Kernel arrays, scene contexts, loading stages and layouts derived from one design.

    Every entry is built once by :meth:`get` and reused; keys name their inputs by value.
    Bounded: when it holds more than ``MAX_ENTRIES`` (randomised payloads, new obstacles
    every episode) it starts afresh.
    """

    MAX_ENTRIES = 256

    def __init__(self, scaled_from: tuple | None = None):
        self._store = {}
        # (nominal design, modulus factor) of a design made by ArmDesign.scaled: its kernel
        # arrays are derived from the nominal's (solver.problem.pack).
        self.scaled_from = scaled_from

    def get(self, key, build):
        """The entry for ``key``, built by ``build()`` the first time."""
        hit = self._store.get(key)
        if hit is None:
            if len(self._store) >= self.MAX_ENTRIES:
                self._store.clear()
            hit = self._store[key] = build()
        return hit

    def peek(self, key):
        """The entry for ``key``, or None (no ``build`` closure to make on the hot path)."""
        return self._store.get(key)

    def __len__(self) -> int:
        return len(self._store)

    def clear(self) -> None:
        self._store.clear()
