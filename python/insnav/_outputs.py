"""Where a command may write, checked before its long work.

An output never replaces one of the command's inputs (compared by device and
inode, symbolic and hard links followed), never replaces an existing file
that insnav did not write (a solution, one of its sidecars, a KF-GINS result
file, a report or an evaluation) unless the user says ``--overwrite``, and
its folder must be writable.  The writes themselves are atomic and all or
nothing (:func:`insnav._atomic.output_set`)."""
from __future__ import annotations

import os
import stat
from pathlib import Path

from .errors import UserError

__all__ = ["input_files", "check_outputs", "check_writable", "insnav_output_kind"]

#: the first line of a resolved run configuration (``<out>.config.toml``)
CONFIG_FIRST_LINE = "# insnav resolved run configuration"


def file_id(path) -> tuple[int, int] | None:
    """(device, inode) of ``path`` (links followed), None when it does not exist."""
    return _file_id(path)


def _file_id(path) -> tuple[int, int] | None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return st.st_dev, st.st_ino


def input_files(*paths) -> dict[tuple[int, int], Path]:
    """(device, inode) -> path of every existing input among ``paths``
    (None skipped; a folder stands for itself and every file directly in it,
    as an insnav dataset folder does)."""
    out: dict[tuple[int, int], Path] = {}
    for p in paths:
        if p is None:
            continue
        p = Path(p)
        fid = _file_id(p)
        if fid is None:
            continue
        out.setdefault(fid, p)
        if p.is_dir():
            try:
                children = list(p.iterdir())
            except OSError:
                continue
            for c in children:
                cid = _file_id(c)
                if cid is not None and c.is_file():
                    out.setdefault(cid, c)
    return out


def head(path, n: int = 4096) -> bytes:
    """The first ``n`` bytes of ``path`` (empty when it cannot be read)."""
    return _head(path, n)


def _head(path, n: int = 4096) -> bytes:
    """Empty for anything but a regular file: reading a named pipe given as an output would block
    until a writer appears (so a FIFO is "a file insnav did not write" and refused)."""
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):
            return b""
        with open(path, "rb") as f:
            return f.read(n)
    except OSError:
        return b""


def _first_line(path) -> str:
    return _head(path).split(b"\n", 1)[0].decode("ascii", "replace").strip().replace(" ", "")


def _numeric_fields(path) -> int:
    """Fields of the first line when all are numbers, else 0."""
    try:
        f = _head(path).split(b"\n", 1)[0].split()
        [float(x) for x in f]
    except ValueError:
        return 0
    return len(f)


#: the first line of an RTKLIB-layout ``.pos`` insnav writes (``% program   : insnav rtk``,
#: ``insnav rtk/ins rtk``), blanks removed as :func:`_first_line` removes them
RTK_POS_FIRST_LINE = "%program:insnav"

#: the first bytes of the TOML ``insnav tune`` writes
TUNED_FIRST_LINE = "# insnav tune:"


def insnav_output_kind(path) -> str | None:
    """What insnav file ``path`` is (``solution``, ``innovations``,
    ``residuals``, ``config``, ``tuned config``, ``spp table``, ``rtk table``, ``rtk pos``,
    ``KF-GINS result``, ``evaluation``), from its name and its first bytes; None for anything
    else (an empty file included; an RTKLIB ``.pos`` another program wrote)."""
    p = Path(path)
    try:
        if not stat.S_ISREG(p.stat().st_mode):  # a named pipe, device or folder: reading a pipe would block
            return None
    except OSError:
        return None
    name = p.name
    if name.endswith(".innovations.csv"):
        return "innovations" if _first_line(p).startswith("t_s,status,applied,nis,rows,") else None
    if name.endswith(".residuals.csv"):
        return "residuals" if _first_line(p).startswith("t_s,prn,elevation_deg,") else None
    if name.endswith(".config.toml"):
        return "config" if _head(p).startswith(CONFIG_FIRST_LINE.encode()) else None
    if name.endswith(".toml") and _head(p).startswith(TUNED_FIRST_LINE.encode()):
        return "tuned config"  # insnav tune --out
    if name.endswith(".spp.csv"):
        return "spp table" if _first_line(p).startswith("t_s,solved,n_sats,") else None
    if name.endswith(".rtk.csv"):
        return "rtk table" if _first_line(p).startswith("t_gps_s,status,ratio,") else None
    if p.suffix.lower() == ".pos":  # RTKLIB's layout; insnav's names itself in the first header line
        return "rtk pos" if _first_line(p).startswith(RTK_POS_FIRST_LINE) else None
    if name.startswith("KF_GINS_"):  # the reader's module only for its names (~2 ms of import)
        from .io.kfgins import KFGINS_IMU_ERR_FILE, KFGINS_NAV_FILE, KFGINS_STD_FILE

        if name in (KFGINS_NAV_FILE, KFGINS_IMU_ERR_FILE, KFGINS_STD_FILE):
            # insnav's --out-format kfgins files, known by the resolved configuration insnav writes beside
            # them; the same files without it are KF-GINS's own results: not insnav's to replace
            want = {KFGINS_NAV_FILE: 11, KFGINS_IMU_ERR_FILE: 13, KFGINS_STD_FILE: 22}[name]
            ours = insnav_output_kind(p.with_name(KFGINS_NAV_FILE + ".config.toml")) == "config"
            return "KF-GINS result" if ours and _numeric_fields(p) == want else None
    suffix = p.suffix.lower()
    if suffix == ".csv":
        return "solution" if _solution_columns(_first_line(p).split(",")) else None
    if suffix == ".npz":
        import zipfile

        try:
            with zipfile.ZipFile(p) as z:
                names = [n[:-4] for n in z.namelist() if n.endswith(".npy")]
        except (OSError, zipfile.BadZipFile):
            return None
        return "solution" if _solution_columns(names) else None
    if suffix == ".parquet":
        try:
            import pyarrow.parquet as pq

            names = list(pq.read_schema(p).names)
        except Exception:  # noqa: BLE001 - not pyarrow's file, or no pyarrow: not recognised
            return None
        return "solution" if _solution_columns(names) else None
    if suffix == ".json":
        import json

        try:
            d = json.loads(p.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        return "evaluation" if isinstance(d, dict) and {"samples", "rms", "max"} <= set(d) else None
    return None


def _solution_columns(names) -> bool:
    """True when ``names`` are a solution's: ``t_s`` (or the older ``t``) and
    nothing but :attr:`insnav.Solution.COLUMNS` (any ``--columns`` groups)."""
    from .filters.solution import LEGACY_COLUMNS, Solution

    names = [LEGACY_COLUMNS.get(n.strip(), n.strip()) for n in names]
    known = (set(Solution.COLUMNS) | set(Solution.ODO_SCALE_COLUMNS) | set(Solution.TIME_OFFSET_COLUMNS)
             | set(Solution.LEVER_ARM_COLUMNS))
    return bool(names) and "t_s" in names and len(names) > 1 and set(names) <= known


def check_writable(folder) -> None:
    """One-line error unless files can be created in ``folder`` (or, when it
    does not exist yet, in its nearest existing parent): tried with a
    temporary file, so a read-only mount or a full inode table shows now,
    not after the run."""
    import tempfile

    folder = Path(folder)
    probe = folder
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if probe.exists() and not probe.is_dir():
        raise UserError(f"cannot write into {folder}: {probe} is not a folder")
    try:
        fd, tmp = tempfile.mkstemp(prefix=".insnav-probe.", dir=probe)
    except OSError as exc:
        raise UserError(f"cannot write into {folder}: {exc.strerror or exc}") from None
    os.close(fd)
    os.unlink(tmp)


def check_outputs(outputs, inputs: dict, *, overwrite: bool = False, option: str = "--out",
                  command: str = "run", replaces: tuple | None = None) -> None:
    """Refuse, with one line naming the file, an output that is one of the
    ``inputs`` (:func:`input_files`), an existing folder, or an existing file
    that is not an insnav output (unless ``overwrite``); and check that every
    output's folder is writable.

    Parameters
    ----------
    outputs : iterable of path
        Every file the command will write.
    inputs : dict
        :func:`input_files` of the command's inputs.
    overwrite : bool
        Replace an existing file that insnav did not write.
    option : str
        Named in the messages (``--out``).
    command : str
        What the inputs are inputs of, for the messages (``run``, ``evaluation``).
    replaces : tuple of str, optional
        The kinds of insnav file (:func:`insnav_output_kind`) the command may replace without
        ``overwrite`` (default: any; ``insnav evaluate --out``: an earlier evaluation only).
    """
    folders = []
    for out in outputs:
        out = Path(out)
        fid = _file_id(out)
        if fid is not None:
            if fid in inputs:
                src = inputs[fid]
                same = "" if Path(os.path.abspath(src)) == Path(os.path.abspath(out)) else f" ({src})"
                raise UserError(f"{option} {out} is an input of this {command}{same}: choose another output name")
            if stat.S_ISDIR(os.stat(out).st_mode):
                raise UserError(f"{option} {out} is a folder: give a file name")
            kind = None if overwrite else insnav_output_kind(out)
            if not overwrite and kind is None:
                raise UserError(f"{out} exists and is not a file insnav wrote: not replaced (choose another "
                                f"{option}, or --overwrite to replace it)")
            if not overwrite and replaces is not None and kind not in replaces:
                raise UserError(f"{out} exists and is an insnav {kind}, not an {' or '.join(replaces)}: not replaced "
                                f"(choose another {option}, or --overwrite to replace it)")
        if out.parent not in folders:
            folders.append(out.parent)
    for f in folders:
        check_writable(f)
