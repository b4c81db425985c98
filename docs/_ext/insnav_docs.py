"""Sphinx directives that generate the CLI and configuration references from
the code, so that they cannot drift from it.

``.. insnav-cli::``
    One section per ``insnav`` sub-command, from the argparse parser
    (:func:`insnav.cli.build_parser`): its description and the full ``--help``
    text, formatted at a fixed width.
``.. insnav-config::``
    One section per TOML table of a run configuration, from the schema in
    ``insnav.config``: the dataclass fields of :class:`insnav.config.RunConfig`
    (top level), ``[constraints]``, ``[robust]`` and every
    :class:`insnav.config.TomlTable` (``[gnss]``, ``[spp]``), the user-unit keys
    of ``[imu]`` and the limits of ``[sanitize]``; for every key its default,
    its type and the description from the class docstring.
"""
from __future__ import annotations

import dataclasses
import importlib
import os
import re

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

HELP_WIDTH = 100


def _section(directive: SphinxDirective, title: str, ident: str) -> nodes.section:
    sec = nodes.section(ids=[nodes.make_id(ident)])
    sec += nodes.title(text=title)
    directive.state.document.note_implicit_target(sec, sec)
    return sec


def _para(text: str) -> nodes.paragraph:
    return nodes.paragraph(text=text)


# --- CLI --------------------------------------------------------------------------

def cli_commands():
    """``[(name, help, formatted --help)]`` of every ``insnav`` sub-command, in help order."""
    import argparse

    from insnav.cli import build_parser

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_WIDTH)  # argparse wraps at $COLUMNS
    try:
        parser = build_parser()
        out = [("insnav", parser.description or "", parser.format_help())]
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                helps = {a.dest: a.help for a in action._choices_actions}
                for name, sub in action.choices.items():
                    out.append((name, helps.get(name) or "", sub.format_help()))
    finally:
        if old is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = old
    return out


class InsnavCli(SphinxDirective):
    has_content = False

    def run(self):
        result = []
        for name, help_, text in cli_commands():
            title = name if name == "insnav" else f"insnav {name}"
            sec = _section(self, title, f"cli-{name}")
            if help_ and name != "insnav":
                sec += _para(help_[0].upper() + help_[1:] + ".")
            block = nodes.literal_block(text, text)
            block["language"] = "text"
            sec += block
            result.append(sec)
        return result


# --- configuration ---------------------------------------------------------------

_ATTR = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*(?:\s*,\s*[A-Za-z_][A-Za-z0-9_]*)*)\s+:\s*(.*)$")


def attribute_docs(doc: str | None) -> dict:
    """``{name: (type text, description)}`` from the ``name[, name2] : type``
    entries of a numpydoc Attributes list (whatever its header says)."""
    out: dict = {}
    lines = (doc or "").expandtabs().splitlines()
    i = 0
    while i < len(lines):
        m = _ATTR.match(lines[i])
        if not m:
            i += 1
            continue
        indent = len(m.group(1))
        names = [n.strip() for n in m.group(2).split(",")]
        body = []
        i += 1
        while i < len(lines) and (not lines[i].strip() or len(lines[i]) - len(lines[i].lstrip()) > indent):
            body.append(lines[i].strip())
            i += 1
        desc = " ".join(" ".join(body).split())
        for n in names:
            out.setdefault(n, (m.group(3).strip(), desc))
    return out


def _default(f: dataclasses.Field):
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:  # type: ignore[misc]
        return f.default_factory()  # type: ignore[misc]
    return None


def _toml(v) -> str:
    if v is None:
        return "(absent)"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return f'"{v}"'
    if dataclasses.is_dataclass(v):
        return "(a table)"
    if isinstance(v, dict):
        return "{}" if not v else "{" + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return repr(v)


def config_tables():
    """``[(table, what, [(key, default, type, description)])]`` of a run configuration."""
    cfg = importlib.import_module("insnav.config")
    for mod in ("insnav.gnss.spp", "insnav.gnss.weighting"):  # the TomlTable subclasses
        importlib.import_module(mod)
    tables = []

    def from_dataclass(table, cls, what, skip=()):
        docs = attribute_docs(cls.__doc__)
        rows = []
        for f in dataclasses.fields(cls):
            if f.name in skip or f.name.startswith("_"):
                continue
            typ, desc = docs.get(f.name, ("", ""))
            rows.append((f.name, _toml(_default(f)), typ or str(f.type), desc))
        tables.append((table, what, rows))

    from_dataclass("top level", cfg.RunConfig,
                   "Keys outside any table: the filter, the coupling, the state layout, initial sigmas, "
                   "gating, output.  Python: insnav.RunConfig.", skip=("imu", "constraints", "robust"))
    imu_doc = attribute_docs(cfg.ImuNoise.__doc__)
    rows = []
    for key, (fld, factor) in cfg._USER_UNITS.items():
        typ, desc = imu_doc.get(fld, ("", ""))
        rows.append((key, "(the dataset's IMU model)", "float or 3 floats >= 0",
                     f"Sets ImuNoise.{fld} (SI = value x {factor:.6g}). {desc}".strip()))
    tables.append(("[imu]", "The IMU noise model given to the filter, in the units of the key names; "
                   "absent keys come from the dataset's IMU model (imu_model or imu_grade).", rows))
    from_dataclass("[constraints]", cfg.Constraints, (cfg.Constraints.__doc__ or "").strip().split("\n\n")[0])
    from_dataclass("[robust]", cfg.Robust, (cfg.Robust.__doc__ or "").strip().split("\n\n")[0])
    rows = [(k, _toml(v), "float", "") for k, v in cfg.SANITIZE_DEFAULTS.items()]
    tables.append(("[sanitize]", "Limits of the input repairs before a run (insnav.filters.sanitize); "
                   "the defaults are in SI.", rows))
    for cls in sorted(_subclasses(cfg.TomlTable), key=lambda c: c.TABLE):
        if cls.TABLE:
            from_dataclass(f"[{cls.TABLE}]", cls, (cls.__doc__ or "").strip().split("\n\n")[0])
    return tables


def _subclasses(cls):
    for c in cls.__subclasses__():
        yield c
        yield from _subclasses(c)


class InsnavConfig(SphinxDirective):
    has_content = False

    def run(self):
        result = []
        for table, what, rows in config_tables():
            sec = _section(self, table, f"config-{table.strip('[]').replace(' ', '-')}")
            sec += _para(" ".join(what.split()))
            tbl = nodes.table(classes=["longtable"])
            tg = nodes.tgroup(cols=4)
            for w in (18, 14, 14, 54):
                tg += nodes.colspec(colwidth=w)
            head = nodes.thead()
            hrow = nodes.row()
            for h in ("key", "default", "type", "meaning"):
                hrow += nodes.entry("", _para(h))
            head += hrow
            tg += head
            body = nodes.tbody()
            for key, default, typ, desc in rows:
                row = nodes.row()
                row += nodes.entry("", nodes.paragraph("", "", nodes.literal(text=key)))
                row += nodes.entry("", nodes.paragraph("", "", nodes.literal(text=default)))
                row += nodes.entry("", _para(typ))
                row += nodes.entry("", _para(desc))
                body += row
            tg += body
            tbl += tg
            sec += tbl
            result.append(sec)
        return result


# --- API reference pages, generated from the package ------------------------------

#: modules that are the command line (documented by the CLI reference), not API
_NOT_API = ("insnav.cli", "insnav.sim.cli", "insnav.__main__")


def public_modules() -> list[str]:
    """Every importable public module of insnav (no ``_`` component, not the CLI)."""
    import pkgutil

    import insnav

    names = ["insnav"]
    for info in pkgutil.walk_packages(insnav.__path__, "insnav."):
        parts = info.name.split(".")
        if any(p.startswith("_") for p in parts) or info.name.startswith(_NOT_API):
            continue
        names.append(info.name)
    return sorted(names)


def public_names(modname: str) -> list[str]:
    """The public names of a module: its ``__all__``, else what it defines
    without a leading underscore (functions, classes)."""
    import inspect

    mod = importlib.import_module(modname)
    if hasattr(mod, "__all__"):
        return list(mod.__all__)
    return [n for n, v in vars(mod).items() if not n.startswith("_")
            and (inspect.isfunction(v) or inspect.isclass(v)) and getattr(v, "__module__", None) == modname]


def write_api_pages(app) -> None:
    """docs/reference/api/<module>.md for every public module (rewritten only
    when its text changes, so an unchanged build stays incremental)."""
    from pathlib import Path

    out = Path(app.srcdir) / "reference" / "api"
    out.mkdir(parents=True, exist_ok=True)
    wanted = set()
    modules = public_modules()
    for modname in modules:
        names = public_names(modname)
        if modname != "insnav" and not names:
            continue
        if modname == "insnav":
            body = ["# insnav (top level)", "",
                    "The names most programs need; each is documented where it is defined.", ""]
            import insnav

            for n in insnav.__all__:
                if n == "__version__":
                    continue
                obj = getattr(insnav, n)
                kind = "autoclass" if isinstance(obj, type) else "autofunction"
                body += ["```{eval-rst}", f".. {kind}:: insnav.{n}", "   :no-index:", "```", ""]
        else:
            # (eval-rst: autodoc writes reStructuredText, which a MyST block would read as Markdown)
            mod = importlib.import_module(modname)
            # a package's name that is also one of its submodules (insnav.ins.mechanize, the
            # function and the module) is documented where it is defined, and only shown here
            shadow = [n for n in names if hasattr(mod, "__path__") and f"{modname}.{n}" in modules]
            # autodoc's automodule documents module-level data only with a "#:" comment:
            # the rest of the public constants get an explicit autodata entry
            import inspect

            from sphinx.pycode import ModuleAnalyzer

            try:
                attr_docs = {k[1] for k in ModuleAnalyzer.for_module(modname).find_attr_docs() if k[0] == ""}
            except Exception:  # (a module without source)
                attr_docs = set()
            bare = [n for n in names if n not in shadow and n not in attr_docs and hasattr(mod, n)
                    and getattr(getattr(mod, n), "__module__", None) in (None, "builtins", "numpy")
                    and not (inspect.isroutine(getattr(mod, n)) or inspect.isclass(getattr(mod, n))
                             or inspect.ismodule(getattr(mod, n)))]
            members = [n for n in names if n not in shadow and n not in bare]
            body = [f"# {modname}", "", "```{eval-rst}", f".. automodule:: {modname}"]
            if members:
                body += ["   :members: " + ", ".join(members), "   :undoc-members:"]
            else:  # (an empty :members: would mean all of them, as would the default)
                body += ["   :no-members:"]
            body += [""]
            for n in bare:
                body += [f".. autodata:: {modname}.{n}", ""]
            for n in shadow:
                body += [f".. autofunction:: {modname}.{n}", "   :no-index:", ""]
            body += ["```", ""]
        text = "\n".join(body)
        p = out / f"{modname}.md"
        wanted.add(p.name)
        if not p.is_file() or p.read_text(encoding="utf-8") != text:
            p.write_text(text, encoding="utf-8")
    for p in out.glob("*.md"):
        if p.name not in wanted:
            p.unlink()


_TITLE_UNDERLINE = re.compile(r"^\s*([-=~^])\1{2,}\s*$")


def module_section_titles_to_bold(app, what, name, obj, options, lines) -> None:
    """A module docstring's section titles (``References`` over ``----------``)
    become bold paragraphs: inside an autodoc entry a title cannot start a
    section, and as a rubric every page's "References" would be one more
    label of the same name."""
    if what != "module":
        return
    i = 1
    while i < len(lines):
        prev = lines[i - 1].strip()
        if prev and _TITLE_UNDERLINE.match(lines[i]) and len(lines[i].strip()) == len(prev) \
                and not _TITLE_UNDERLINE.match(lines[i - 1]):
            lines[i - 1] = f"**{prev}**"
            lines[i] = ""
        i += 1


def setup(app):
    app.connect("builder-inited", write_api_pages)
    app.connect("autodoc-process-docstring", module_section_titles_to_bold, priority=100)
    app.add_directive("insnav-cli", InsnavCli)
    app.add_directive("insnav-config", InsnavConfig)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
