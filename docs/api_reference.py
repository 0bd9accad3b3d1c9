"""Write docs/api.md, the reference of ``import cosim``, from the docstrings of its public names.

    python docs/api_reference.py            # rewrite docs/api.md
    python docs/api_reference.py --check    # exit 1 when docs/api.md is not what the docstrings give

Every name of ``cosim.__all__`` gets its signature and its whole docstring; a class also gets its public
methods and properties defined in cosim (those of object, Exception or typing are left out).  Names are listed
in the order of ``cosim.__all__`` within three groups (functions, classes, errors).  tests/project/test_api_reference.py
checks that every public name and method has a docstring and that docs/api.md is up to date, so the reference
cannot drift from the code.
"""

from __future__ import annotations

import argparse
import inspect
import sys
from pathlib import Path
from typing import Any

HERE = Path(__file__).resolve().parent
API_MD = HERE / "api.md"

HEADER = """# API reference: `import cosim`

Generated from the docstrings by `python docs/api_reference.py` (do not edit by hand; the tests check that it is
up to date). The command line is described in the [README](../README.md), the spec in [spec.md](spec.md), the
package's layers in [architecture.md](architecture.md).
"""


def public_names() -> list[str]:
    import cosim

    return [name for name in cosim.__all__ if not name.startswith("_")]


def _signature(obj: Any) -> str:
    try:
        return str(inspect.signature(obj))
    except (TypeError, ValueError):  # a builtin without a signature
        return "(...)"


def members(cls: type) -> list[tuple[str, Any]]:
    """The public methods and properties ``cls`` (or a cosim base of it) defines, in definition order."""
    seen: dict[str, Any] = {}
    for klass in reversed(cls.__mro__):
        if not klass.__module__.startswith("cosim"):
            continue
        for name, value in vars(klass).items():
            if name.startswith("_") and name != "__init__":
                continue
            if isinstance(value, (staticmethod, classmethod)):
                value = getattr(cls, name)  # bound to the class: no ``cls`` in its signature
            if inspect.isfunction(value) or inspect.ismethod(value) or isinstance(value, property):
                seen[name] = value
    init = seen.pop("__init__", None)
    return ([("__init__", init)] if init is not None else []) + list(seen.items())


def _member_text(cls_name: str, name: str, value: Any) -> str:
    doc = inspect.getdoc(value) or ""
    if isinstance(value, property):
        head = f"#### `{cls_name}.{name}` (property)"
    elif name == "__init__":
        head = f"#### `{cls_name}{_signature(value).replace('(self, ', '(').replace('(self)', '()')}`"
    else:
        head = f"#### `{cls_name}.{name}{_signature(value).replace('(self, ', '(').replace('(self)', '()')}`"
    return f"{head}\n\n{doc}\n" if doc else f"{head}\n"


def entry(name: str, obj: Any) -> str:
    """The Markdown of one public name."""
    doc = inspect.getdoc(obj) or ""
    if inspect.isclass(obj):
        bases = [b.__name__ for b in obj.__bases__ if b is not object]
        text = f"### class `{name}`" + (f"({', '.join(bases)})" if bases else "") + f"\n\n{doc}\n"
        for member, value in members(obj):
            if member == "__init__" and (inspect.getdoc(value) or "") == doc:
                continue
            text += "\n" + _member_text(name, member, value)
        return text
    if callable(obj):
        return f"### `{name}{_signature(obj)}`\n\n{doc}\n"
    return f"### `{name}` = `{obj!r}`\n"


def reference() -> str:
    """The whole text of docs/api.md."""
    import cosim

    groups: dict[str, list[str]] = {"Functions": [], "Classes": [], "Errors": []}
    for name in public_names():
        obj = getattr(cosim, name)
        if inspect.isclass(obj) and issubclass(obj, BaseException):
            groups["Errors"].append(entry(name, obj))
        elif inspect.isclass(obj):
            groups["Classes"].append(entry(name, obj))
        elif callable(obj):
            groups["Functions"].append(entry(name, obj))
    version = f"`cosim.__version__` is the package's version ({cosim.__version__} when this page was made).\n"
    parts = [HEADER, version]
    for title, entries in groups.items():
        parts.append(f"## {title}\n")
        parts.extend(entries)
    return "\n".join(parts).rstrip() + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="only check that docs/api.md is up to date")
    args = parser.parse_args()
    text = reference()
    if args.check:
        if API_MD.exists() and API_MD.read_text(encoding="utf-8") == text:
            return 0
        print(f"{API_MD} is not up to date: run python docs/api_reference.py", file=sys.stderr)
        return 1
    API_MD.write_text(text, encoding="utf-8")
    print(f"written: {API_MD}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
