"""The exceptions of lfrefract: every error it raises on purpose is one of these.

All three derive from :class:`ValueError`, so code that catches ``ValueError`` keeps working; a CLI
catches these, prints the message (which names the parameter or the file and the value) and exits
with status 2.
"""

from __future__ import annotations

__all__ = ["CalibrationError", "FileFormatError", "ParameterError"]


class ParameterError(ValueError):
    """A parameter has an impossible, non-finite or unknown value."""


class FileFormatError(ValueError):
    """A file is missing, of the wrong kind, or does not hold what it should."""


class CalibrationError(ParameterError):
    """The observations do not determine the parameters (degenerate or inconsistent views)."""
