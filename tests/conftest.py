"""Shared fixtures: where the third-party data lives (../shared/data beside the repo)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("INSNAV_SHARED_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ``../shared/data``; skips the test when it is absent (e.g. wheel-only install)."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"third-party data not found at {SHARED_DATA} (set INSNAV_SHARED_DATA)")
    return SHARED_DATA


def short_tight_dataset(duration_s: float = 120.0, seed: int = 7):
    """seed003-4sat cut to its first motion segments (>= duration_s), up to 8
    satellites, no failure windows: a tight-coupling run of about a second."""
    import insnav.sim as sim

    sc = dict(sim.simulate("seed003-4sat", seed=0, with_truth=False).scenario)
    segs, tot = [], 0.0
    for seg in sc["motion"]["segments"]:
        if tot >= duration_s:
            break
        segs.append(seg)
        tot += float(seg["duration_s"])
    sc["motion"] = dict(sc["motion"], segments=segs)
    sc["gnss_raw"] = dict(sc["gnss_raw"], windows=[], max_sats=8)
    return sim.simulate(sc, seed=seed)
