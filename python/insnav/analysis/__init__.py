"""Analysis of solutions: errors against a truth (:mod:`.metrics`), the
evaluation of a saved solution (:mod:`.evaluate`), fault injection and
scoring (:mod:`.faults`), Monte Carlo campaigns (:mod:`.montecarlo`)."""
from __future__ import annotations

from .metrics import errors, reconvergence_time, recovery_metrics, rms

__all__ = ["errors", "reconvergence_time", "recovery_metrics", "rms"]
