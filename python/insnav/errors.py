"""Exceptions that name what the user has to fix."""
from __future__ import annotations

__all__ = ["UserError"]


class UserError(Exception):
    """An error in the user's input: the CLI prints it as one line and exits with status 2."""
