"""Subcommands of the ``softarm`` command line (see :mod:`softarm_gym.cli`)."""
