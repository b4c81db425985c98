"""The input formats of ``insnav run`` (``--format``), one registry.

Each :class:`InputFormat` names its command-line arguments (the files it
reads), the arguments it refuses, and its loader ``load(files) -> (Dataset,
RunConfig, tables)``: the dataset, the run configuration it resolved (the
format's TOML keys included) and the format's own resolved tables, written
back into ``<out>.config.toml`` so that the run repeats.  ``insnav run``
reads only this table to check the arguments and load the data, so a new
format is one entry here and its loader module.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

__all__ = ["InputFormat", "INPUT_FORMATS", "input_format", "Loaded"]


@dataclass
class Loaded:
    """What a format's loader returns: the dataset, the resolved run configuration and the
    format's own resolved tables (``rinex``: the RinexOptions; ``csv``: the file-mapping tables)."""

    dataset: object
    config: object
    tables: dict


@dataclass(frozen=True)
class InputFormat:
    """One ``--format``.

    Attributes
    ----------
    name : str
        The ``--format`` value.
    required : tuple of str
        The arguments it needs (``obs``, ``nav``, ``imu``, ``gnss``, ``config``, ``dataset``).
    optional : tuple of str
        The other arguments it reads.
    needs : str
        Why the required arguments are needed (the end of the error message).
    load : callable
        ``load(args) -> Loaded`` (``args`` has the attributes named above).
    summary : str
        One line for the help.
    """

    name: str
    required: tuple
    optional: tuple
    load: Callable
    summary: str
    needs: str = ""

    def check(self, args) -> None:
        """A ValueError naming what is missing or does not belong to this format."""
        missing = [n for n in self.required if not getattr(args, n, None)]
        if missing:
            flags = ", ".join("a dataset directory" if n == "dataset" else f"--{n.replace('_', '-')}"
                              for n in missing)
            raise ValueError(f"--format {self.name} needs {flags}{self.needs}")
        if "dataset" in self.required and not Path(args.dataset).is_dir():
            raise ValueError(f"dataset directory not found: {args.dataset}")
        reads = "/".join(f"--{n}" for n in self.required if n not in ("config", "dataset"))
        if reads and getattr(args, "dataset", None):
            raise ValueError(f"--format {self.name} reads {reads}; do not give a dataset directory")


def _load_insnav(args) -> Loaded:
    import insnav
    from ..config import RunConfig, load_config

    ds = insnav.load_dataset(args.dataset)
    cli = dict(filter=getattr(args, "filter", None), coupling=getattr(args, "coupling", None))
    return Loaded(ds, load_config(args.config, cli) if args.config else RunConfig(), {})


def _load_rinex(args) -> Loaded:
    from .rinex_dataset import load_rinex_run

    nav = [p for p in args.nav.split(",") if p]  # several files merged (a RINEX 2 .n and .g pair)
    ds, cfg = load_rinex_run(args.obs, nav if len(nav) > 1 else args.nav, args.imu, args.config,
                             imu_tag=getattr(args, "imu_tag", None))
    return Loaded(ds, cfg, {"rinex": ds.options})


def _load_csv(args) -> Loaded:
    from .csv_dataset import load_csv_run

    ds, cfg = load_csv_run(args.imu, args.gnss, args.config, imu_tag=getattr(args, "imu_tag", None))
    return Loaded(ds, cfg, {"csv": ds.info["tables"]})


def _load_kfgins(args) -> Loaded:
    from .kfgins_dataset import load_kfgins

    ds, cfg = load_kfgins(args.config, getattr(args, "imu", None), getattr(args, "gnss", None))
    return Loaded(ds, cfg, {})


INPUT_FORMATS: dict[str, InputFormat] = {f.name: f for f in (
    InputFormat("insnav", ("dataset",), ("config",), _load_insnav,
                "a dataset directory written by `insnav simulate` (or Dataset.save)",
                needs=": give a dataset directory (or --format kfgins --config FILE)"),
    InputFormat("kfgins", ("config",), ("imu", "gnss"), _load_kfgins,
                "KF-GINS files: the YAML configuration and the IMU and GNSS text files it names",
                needs=" KF-GINS.yaml"),
    InputFormat("rinex", ("obs", "nav", "imu"), ("config", "imu_tag"), _load_rinex,
                "RINEX 2/3 observation and navigation files and an IMU CSV (tight coupling)"),
    InputFormat("csv", ("imu", "gnss", "config"), ("imu_tag",), _load_csv,
                "your IMU CSV and GNSS fixes (CSV, RTKLIB .pos or NMEA) mapped by the config's [imu] and [gnss]",
                needs=" (the [imu] and [gnss] tables of --config map the files)"),
)}


def input_format(name: str) -> InputFormat:
    """The registered format; a ValueError naming the known ones."""
    try:
        return INPUT_FORMATS[name]
    except KeyError:
        raise ValueError(f"--format {name!r} unknown; known: {', '.join(INPUT_FORMATS)}") from None
