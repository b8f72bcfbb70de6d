"""The registered ``SoftArm/*`` ids: which exist, which are out of date, and building one.

Gymnasium warns "The environment ... is out of date" whenever ``gym.make`` builds an id of which
a later version is registered. That is right for a user who typed the id, and noise for a
command that goes through every registered id (``softarm warmup``, the benchmarks, the stress
test): those build envs with :func:`make_unwrapped` (no ``gym.make``) or :func:`make` with
``quiet=True``.
"""

from __future__ import annotations

import re
import warnings

import gymnasium as gym
from gymnasium.envs.registration import load_env_creator

__all__ = ["env_ids", "recommended_ids", "latest", "is_deprecated", "make", "make_unwrapped"]

PREFIX = "SoftArm/"

_VERSION = re.compile(r"^(?P<name>.+)-v(?P<version>\d+)$")


def env_ids(include_deprecated: bool = True) -> tuple[str, ...]:
    """Registered soft-arm ids in registration order (``import softarm_gym`` registers them);
    without the out-of-date ones if ``include_deprecated`` is False."""
    import softarm_gym  # noqa: F401  (registers the ids)

    ids = tuple(env_id for env_id in gym.registry if env_id.startswith(PREFIX))
    return ids if include_deprecated else tuple(i for i in ids if not is_deprecated(i))


def recommended_ids() -> tuple[str, ...]:
    """The ids to use: the latest version of each registered name."""
    return env_ids(include_deprecated=False)


def latest(env_id: str) -> str:
    """The latest registered version of ``env_id``'s name (``env_id`` itself if it is the latest)."""
    match = _VERSION.match(env_id)
    if match is None:
        raise ValueError(f"{env_id!r} is not a versioned id NAME-vN")
    versions = [int(m.group("version")) for other in env_ids()
                if (m := _VERSION.match(other)) and m.group("name") == match.group("name")]
    return f"{match.group('name')}-v{max(versions, default=int(match.group('version')))}"


def is_deprecated(env_id: str) -> bool:
    """True when a later version of ``env_id`` is registered (``gym.make`` warns for it)."""
    return latest(env_id) != env_id


def make(env_id: str, quiet: bool = False, **kwargs):
    """``gym.make(env_id, **kwargs)``; ``quiet=True`` drops Gymnasium's "out of date" warning,
    for commands that build every registered id rather than one the user named."""
    if not quiet:
        return gym.make(env_id, **kwargs)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*is out of date.*")
        return gym.make(env_id, **kwargs)


def make_unwrapped(env_id: str, **kwargs):
    """The env class of ``env_id`` built with its registered kwargs updated by ``kwargs``, without
    ``gym.make``'s wrappers (time limit, order enforcing, checker) or its warnings."""
    spec = gym.spec(env_id)
    creator = load_env_creator(spec.entry_point) if isinstance(spec.entry_point, str) else spec.entry_point
    return creator(**{**spec.kwargs, **kwargs})
