"""Exceptions that name what the user has to fix."""
from __future__ import annotations

__all__ = ["InsnavWarning", "UserError", "close_matches"]


class UserError(Exception):
    """An error in the user's input: the CLI prints it as one line and exits with status 2."""


class InsnavWarning(UserWarning):
    """A result the user should know how it was made (e.g. a model's default coefficients in place of
    missing broadcast ones): the CLI prints it as one line, ``warning: ...``."""


def close_matches(name, known) -> list[str]:
    """The known name closest to a misspelt ``name`` (a list of at most one,
    empty when none is close): every "did you mean" in insnav comes from here."""
    import difflib

    return difflib.get_close_matches(str(name), [str(k) for k in known], n=1, cutoff=0.6)


def seed_arg(text: str) -> int:
    """argparse ``type`` of a ``--seed`` option: an integer >= 0 (numpy's generators take
    no negative seed), else argparse's one-line error naming the option."""
    import argparse

    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {text!r}") from None
    if v < 0:
        raise argparse.ArgumentTypeError(f"expected an integer >= 0, got {v}")
    return v
