"""Reading spec.json strictly: only what JSON allows, every key once, bounded nesting.

Python's ``json`` module accepts more than JSON: ``NaN``, ``Infinity`` and
numbers such as ``1e400`` (which become infinite), and a key given twice
(the last one silently wins).  It also recurses once per nesting level, so a
spec nested a thousand levels deep ends in RecursionError.  :func:`parse_spec_json`
refuses all of these with one problem each, naming the JSON path.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from cosim.errors import Problem, SpecError, json_path
from cosim.util import limits


class _NotJson:
    """Stands in for a value JSON does not allow, until its path is known."""

    def __init__(self, text: str):
        self.text = text


class _Object(dict):
    """A JSON object that remembers the keys it had more than once."""

    duplicates: tuple[str, ...] = ()


def _object(pairs: list[tuple[str, Any]]) -> _Object:
    obj = _Object(pairs)
    if len(obj) != len(pairs):
        seen: set[str] = set()
        obj.duplicates = tuple(k for k, _ in pairs if k in seen or seen.add(k))  # type: ignore[func-returns-value]
    return obj


def _float(text: str) -> Any:
    value = float(text)
    return value if math.isfinite(value) else _NotJson(text)


def parse_spec_json(text: str, file: str) -> Any:
    """The parsed spec (plain dicts and lists); raises SpecError for anything strict JSON refuses.

    Problems: malformed JSON (line and column), ``NaN``/``Infinity`` or a
    number too large for a float (its path), a key given twice (its path;
    cosim does not pick one), nesting deeper than the ``json_depth`` limit.
    """
    try:
        raw = json.loads(text, object_pairs_hook=_object, parse_constant=_NotJson, parse_float=_float)
    except json.JSONDecodeError as exc:
        raise SpecError([Problem(file, "$", f"malformed JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}",
                                 "fix the JSON syntax there (a missing comma or quote is the usual cause)")]) from None
    except RecursionError:
        raise SpecError([Problem(file, "$", "arrays or objects are nested too deeply to read",
                                 f"nest at most {limits.limit('json_depth')} levels")]) from None
    except ValueError as exc:  # e.g. an integer with more digits than Python converts
        raise SpecError([Problem(file, "$", f"a number cannot be read: {exc}",
                                 "write numbers of ordinary size")]) from None
    problems = _walk(raw, file)
    if problems:
        raise SpecError(problems)
    return _plain(raw)


def read_spec_json(path: str | Path) -> Any:
    """Read and parse the spec file at ``path`` strictly (see :func:`parse_spec_json`)."""
    name = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError([Problem(name, "$", "file not found", "check the path of the spec file")]) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError([Problem(name, "$", f"cannot read the file: {exc}", "save it as UTF-8 text")]) from None
    return parse_spec_json(text, name)


def _walk(raw: Any, file: str) -> list[Problem]:
    """Problems of values JSON does not allow, duplicate keys and depth; iterative, so any depth is safe."""
    max_depth = int(limits.limit("json_depth"))
    problems: list[Problem] = []
    stack: list[tuple[Any, tuple, int]] = [(raw, (), 0)]
    while stack:
        value, parts, depth = stack.pop()
        if isinstance(value, _NotJson):
            problems.append(Problem(file, json_path(parts), f"{value.text} is not a JSON number (JSON allows only "
                                    "finite numbers)", "write a finite number"))
        elif isinstance(value, (dict, list)):
            if depth >= max_depth:
                problems.append(Problem(file, json_path(parts), f"nested more than {max_depth} levels deep",
                                        f"flatten it; {limits.raise_hint('json_depth')}"))
                continue
            if isinstance(value, _Object):
                for key in value.duplicates:
                    problems.append(Problem(file, json_path([*parts, key]), f"key '{key}' is given more than once; "
                                            "cosim does not guess which one you meant", "keep one of them"))
            items = value.items() if isinstance(value, dict) else enumerate(value)
            # only what can hold a problem: 10^5 connections hold 3 x 10^5 plain strings
            stack.extend((v, (*parts, k), depth + 1) for k, v in items if isinstance(v, (dict, list, _NotJson)))
    return sorted(problems, key=lambda p: p.path)


def _plain(value: Any) -> Any:
    """Plain dicts instead of _Object (the depth is bounded by now, so recursion is safe)."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_plain(v) for v in value]
    return value
