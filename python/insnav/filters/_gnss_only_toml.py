"""The top-level keys of a GNSS-only run's TOML (``--filter spp``, ``--filter rtk``): those runs read
their own tables only, so any other key in a TOML meant for them would be ignored without a word."""
from __future__ import annotations

from ..config import ConfigError, _suggest

__all__ = ["check_gnss_only_toml_keys"]


def check_gnss_only_toml_keys(d: dict, source: str, filter_name: str, tables: dict) -> None:
    """ConfigError (one line naming the file and key) for a top-level key a GNSS-only run
    (``filter_name``: spp, rtk) would not read, in a TOML that names no other filter.  ``tables``:
    the tables it reads, each with the keys of its dataclass (for the hint where a key of one of
    them was written at the top level).  ``smooth`` and ``tdcp`` pass: the command line refuses
    them with a line of their own.  ``coupling`` other than ``"gnss"`` is refused.  A TOML of another
    filter (an INS run's, with its ``[imu]``; a ``coupling`` of an INS filter without a ``filter``
    key) is read for the run's tables only."""
    coupling = d.get("coupling", "gnss")
    if d.get("filter", filter_name) != filter_name or ("filter" not in d and coupling in ("loose", "tight", "rtk")):
        return  # another filter's TOML (an INS filter's coupling without a filter key: the default ekf)
    if coupling != "gnss":  # read by no one before: a misspelt or an INS coupling in a GNSS-only TOML
        hint = "; RTK/INS (the IMU with carrier phase) is --filter ekf --coupling rtk" if coupling == "rtk" else ""
        raise ConfigError(f"{source}: key 'coupling': bad value {coupling!r}; allowed: \"gnss\" (filter "
                          f"'{filter_name}' is GNSS only){hint}")
    allowed = ("filter", "coupling", *tables, "smooth", "tdcp")
    names = [f"[{t}]" for t in tables]
    where = names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]
    for k in d:
        if k in allowed:
            continue
        home = next((t for t, keys in tables.items() if k in keys), None)
        hint = f"; did you mean '{home}.{k}' (a key of the [{home}] table)?" if home else _suggest(k, allowed)
        raise ConfigError(f"{source}: key '{k}' is not read by filter '{filter_name}' (it reads {where}){hint}")
