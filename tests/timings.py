"""Comparing results across backends and chunkings: everything but the wall-clock figures."""

TIMING_KEYS = frozenset({"seconds", "seconds_full", "seconds_cc", "time_ms", "steps_per_s"})


def without_timings(obj):
    """``obj`` (a command's JSON or a result dict) with every timing field removed, recursively."""
    if isinstance(obj, dict):
        return {k: without_timings(v) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [without_timings(v) for v in obj]
    return obj
