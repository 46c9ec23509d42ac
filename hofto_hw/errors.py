"""Errors that reach a user as one clear line.

Raise :class:`UserError` (or a subclass) for anything the user can fix: a malformed file, a
missing interface, a recording with NaN rows. The message names the file, field or device.
The CLI prints it without a traceback.
"""

from __future__ import annotations


class UserError(Exception):
    """An error the user can act on; ``str(err)`` is the whole message."""


class ConfigError(UserError):
    """A configuration file or value is wrong; the message names file, field path and value."""


class ModelError(UserError):
    """A robot model or parameter set cannot be used (bad URDF, non-SPD mass matrix, ...)."""
