"""A TOML writer (tomllib only reads): the one used for scenario files,
dataset folders and the effective run configuration."""
from __future__ import annotations

import math
import sys

__all__ = ["dumps_toml", "toml_value", "table_toml"]


def _numpy_types():
    """numpy's integer, floating and array types when numpy is loaded (a value cannot be one of
    them otherwise: the RTK command line runs without numpy), else empty tuples."""
    np = sys.modules.get("numpy")
    if np is None:
        return (), (), ()
    return (np.integer,), (np.floating,), (np.ndarray,)


def toml_value(v) -> str:
    np_int, np_float, np_array = _numpy_types()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, *np_int)):
        return str(int(v))
    if isinstance(v, (float, *np_float)):
        v = float(v)
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if math.isnan(v):
            return "nan"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple, *np_array)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def dumps_toml(d: dict, _prefix: str = "") -> str:
    """Serialise a nested dict (scalars, lists, tables, arrays of tables) to TOML."""
    lines = []
    tables, arrays = [], []
    for k, v in d.items():
        if isinstance(v, dict):
            tables.append((k, v))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            arrays.append((k, v))
        else:
            lines.append(f"{k} = {toml_value(v)}")
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in tables:
        name = f"{_prefix}.{k}" if _prefix else k
        out += f"\n[{name}]\n" + dumps_toml(v, name)
    for k, v in arrays:
        name = f"{_prefix}.{k}" if _prefix else k
        for item in v:
            out += f"\n[[{name}]]\n" + dumps_toml(item, name)
    return out


def table_toml(name: str, obj) -> str:
    """A ``[name]`` TOML table of a dataclass's fields or a dict's items (None left out)."""
    lines = [f"\n[{name}]"]
    if isinstance(obj, dict):
        items = obj.items()
    else:
        import dataclasses  # here: it imports inspect (~10 ms), which the RTK command's dict table does not need

        items = ((f.name, getattr(obj, f.name)) for f in dataclasses.fields(obj))
    for key, v in items:
        if v is None:
            continue
        if isinstance(v, dict):
            lines.append(f"{key} = {{" + ", ".join(f"{k} = {toml_value(x)}" for k, x in v.items()) + "}")
        elif isinstance(v, (list, tuple)) and v and isinstance(v[0], str):
            lines.append(f"{key} = [" + ", ".join(toml_value(x) for x in v) + "]")
        else:
            lines.append(f"{key} = {toml_value(v)}")
    return "\n".join(lines) + "\n"
