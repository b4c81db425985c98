"""Inertial navigation without a filter: batch free-inertial mechanization
(:mod:`.mechanize`) and initial alignment (:mod:`.align`)."""
from __future__ import annotations

from .mechanize import mechanize

__all__ = ["mechanize"]
