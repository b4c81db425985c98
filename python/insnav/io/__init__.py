"""File readers and writers.

- :mod:`insnav.io.kfgins`, :mod:`insnav.io.kfgins_dataset`: KF-GINS text formats
  and configuration (``load_kfgins``).
- :mod:`insnav.io.csv_dataset`: a user's own IMU CSV + GNSS CSV / RTKLIB
  ``.pos`` / NMEA, loosely coupled, initial state from the alignment
  (``load_csv_dataset``); readers in :mod:`insnav.io.imu_csv` (the one IMU
  column-mapping reader) and :mod:`insnav.io.gnss_files`.
- :mod:`insnav.io.input_formats`: the registry of ``insnav run --format``
  (name, command-line arguments, loader).
- :mod:`insnav.io.rinex_dataset`: real GNSS + IMU data for the tight filter:
  RINEX obs + nav, an IMU CSV (or a str2str-tagged raw log) and an RTKLIB
  ``.pos`` reference (``load_rinex``, ``load_rinex_run``).

The names below are imported on first use (``insnav.io.load_rinex``), so
``import insnav.io`` stays cheap.
"""

_LAZY = {name: "rinex_dataset" for name in (
    "load_rinex", "load_rinex_run", "RinexDataset", "RinexOptions", "ImuCsvFormat", "ImuFileError",
    "read_imu_csv", "read_str2str_tag", "single_point_solution", "rtklib_truth")}
_LAZY["load_kfgins"] = "kfgins_dataset"
_LAZY.update({name: "csv_dataset" for name in ("load_csv_dataset", "CsvDataset")})
_LAZY.update({name: "gnss_files" for name in ("read_gnss", "GnssFileFormat", "GnssFileError", "write_pos",
                                              "write_nmea")})

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
