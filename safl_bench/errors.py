"""User-facing errors.

Anything the user can fix (a bad file, a wrong id, a bad value) is raised as a `SaflError`
subclass with a message that names the file or value. The CLI prints such errors on one line and
exits with status 2; everything else is a bug and keeps its traceback.
"""

from __future__ import annotations


class SaflError(Exception):
    """Base class of errors caused by input the user controls."""


class DataError(SaflError):
    """A data file or directory is missing, malformed or inconsistent."""


class ConfigError(SaflError, ValueError):
    """A configuration value is out of range or inconsistent."""


class RegistryError(SaflError, KeyError):
    """An unknown or duplicate task or method id."""

    def __str__(self) -> str:  # KeyError would quote the message
        return str(self.args[0]) if self.args else ""
