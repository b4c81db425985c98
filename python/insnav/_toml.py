"""A TOML writer (tomllib only reads): the one used for scenario files,
dataset folders and the effective run configuration."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["dumps_toml", "toml_value"]


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        v = float(v)
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        if math.isnan(v):
            return "nan"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, (list, tuple, np.ndarray)):
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
