"""Errors of the ROS 2 bag tools: one clear line each (the CLI prints them without a traceback)."""

from app.ocslam.config import ConfigError


class BagError(ValueError):
    """A bag cannot be read or replayed: missing, corrupt, or without the topics replay needs."""


class RecordError(BagError, ConfigError):
    """A bag cannot be created (the ``--record`` path exists, or is not writable)."""
