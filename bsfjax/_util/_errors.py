"""Exception types of bsfjax.  All are ``ValueError`` subclasses so that callers that
already guard numeric code with ``except ValueError`` keep working."""

from __future__ import annotations


class BSFError(ValueError):
    """Base class of every error bsfjax raises on bad input."""


class MeshError(BSFError):
    """A mesh file or mesh array is unusable; the message names the file (if any) and why."""
