"""SSP XML: a hardened parser, the official schemas, and element paths for messages.

Every SSP file (.ssd, .ssv, .ssm) is read up to ``COSIM_SSP_FILE_MB`` (a
bigger file is refused before it is parsed: lxml's tree takes about 13 times
the file's size; see :mod:`.bounds`), parsed without entity expansion, without network access,
without DTD loading and with lxml's size limits on, then checked against the
official SSP schemas shipped in ``schema/`` (see its README).  An entity
reference (``&name;``) left in the text is refused: it is never expanded, and
lxml's schema check cannot walk it.  Problems name the file, the element path (``/ssd:SystemStructure
Description/ssd:System[@name='root']/...``) and the fix.
"""

from __future__ import annotations

import re
from functools import lru_cache
from itertools import islice
from pathlib import Path
from typing import Any

from lxml import etree

from cosim.errors import Problem
from cosim.ssp.bounds import read_bounded

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "ssm": "http://ssp-standard.org/SSP1/SystemStructureParameterMapping",
    "ssb": "http://ssp-standard.org/SSP1/SystemStructureSignalDictionary",
}
_PREFIX = {uri: prefix for prefix, uri in NS.items()}
SCHEMA_DIR = Path(__file__).resolve().parent / "schema"
SCHEMAS = {"ssd": "SystemStructureDescription.xsd", "ssv": "SystemStructureParameterValues.xsd",
           "ssm": "SystemStructureParameterMapping.xsd"}


def hardened_parser() -> etree.XMLParser:
    """An lxml parser that never expands entities, never loads a DTD and never touches the network."""
    return etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, load_dtd=False,
                           dtd_validation=False, remove_blank_text=False)


@lru_cache(maxsize=None)
def _schema(kind: str) -> etree.XMLSchema:
    # the schemas import SystemStructureCommon.xsd by a relative file name, resolved next to them
    return etree.XMLSchema(etree.parse(str(SCHEMA_DIR / SCHEMAS[kind]), hardened_parser()))


def tag(prefix: str, name: str) -> str:
    """The Clark name ``{namespace}name`` of ``prefix:name``."""
    return f"{{{NS[prefix]}}}{name}"


def short_name(clark: str) -> str:
    """``ssd:Component`` for ``{...SystemStructureDescription}Component``."""
    if clark.startswith("{"):
        uri, _, local = clark[1:].partition("}")
        return f"{_PREFIX.get(uri, uri)}:{local}"
    return clark


def display_name(element: etree._Element) -> str:
    """``ssd:Component``; an element of a tool's own namespace by the prefix its file gives it (``oms:...``)."""
    clark = element.tag
    if clark.startswith("{") and clark[1:].partition("}")[0] not in _PREFIX and element.prefix:
        return f"{element.prefix}:{clark.partition('}')[2]}"
    return short_name(clark)


def element_path(element: etree._Element) -> str:
    """A readable XPath-like path: named elements by ``[@name='...']``, others by position when repeated."""
    parts = []
    node = element
    while node is not None and isinstance(node.tag, str):
        step = display_name(node)
        name = node.get("name")
        parent = node.getparent()
        if name is not None:
            step += f"[@name='{name}']"
        elif parent is not None:
            position, alike = _position(parent, node)
            if alike > 1:
                step += f"[{position}]"
        parts.append(step)
        node = parent
    return "/" + "/".join(reversed(parts))


_POSITIONS: dict[Any, tuple[dict, dict]] = {}  # parent -> (child -> position among its tag, tag -> count)
_MANY = 64  # children above which a parent's positions are kept, not counted again per path


def _position(parent: etree._Element, node: etree._Element) -> tuple[int, int]:
    """(1-based position of ``node`` among its parent's children of its tag, how many there are).

    A problem per connection of 10^5 ``ssd:Connection`` siblings counted the siblings once per problem
    (quadratic; lxml's ``len`` walks the children too); a parent of many children has its positions counted
    once and kept (the last few parents; the cache holds them, so their proxies, and so the identity of their
    children, stay the same; documents are not changed once their paths are taken).
    """
    kept = _POSITIONS.get(parent)
    if kept is not None and node in kept[0]:
        return kept[0][node], kept[1][node.tag]
    first = list(islice(parent, _MANY + 1))
    if len(first) <= _MANY:
        same = [c for c in first if c.tag == node.tag]
        return same.index(node) + 1, len(same)
    positions: dict = {}
    counts: dict = {}
    for child in parent:
        if isinstance(child.tag, str):
            counts[child.tag] = positions[child] = counts.get(child.tag, 0) + 1
    if len(_POSITIONS) >= 8:
        _POSITIONS.pop(next(iter(_POSITIONS)))
    _POSITIONS[parent] = (positions, counts)
    return positions[node], counts[node.tag]


def forget_positions() -> None:
    """Drop the kept positions (and so the documents they hold): at the end of a reading."""
    _POSITIONS.clear()


def _readable(message: str) -> str:
    for uri, prefix in _PREFIX.items():
        message = message.replace(f"{{{uri}}}", f"{prefix}:")
    return message


def parse_file(path: Path, label: str, kind: str) -> tuple[etree._Element | None, list[Problem]]:
    """Parse and schema-check one SSP file; ``label`` is how problems name it.

    Returns the root element (None when the file cannot be parsed: missing,
    above ``COSIM_SSP_FILE_MB``, malformed, or holding an entity reference)
    and the problems found; a file that parses but breaks the schema still
    returns its root so that later checks can add their own problems.
    """
    data, problems = read_bounded(path, label)
    if data is None:
        return None, problems
    try:
        root = etree.fromstring(data, hardened_parser(), base_url=str(path))
    except etree.XMLSyntaxError as exc:
        line = exc.lineno if exc.lineno is not None else "?"
        if "XML_PARSE_HUGE" in (exc.msg or ""):  # lxml's own bounds, which cosim keeps on
            return None, [Problem(label, f"line {line}", "the file exceeds the XML parser's safety limits: "
                                  + _readable(exc.msg).replace(", try XML_PARSE_HUGE", "").replace(
                                      ", use XML_PARSE_HUGE option", "").replace("\n", ""),
                                  "shorten the element there (a text or attribute is limited to 10 MB, nesting "
                                  "to 256 levels); cosim does not lift these limits")]
        return None, [Problem(label, f"line {line}", f"malformed XML: {_readable(exc.msg)}",
                              "fix the XML syntax there (an unclosed tag or quote is the usual cause)")]
    entities = entity_problems(root, label)
    if entities:
        return None, entities
    return root, schema_problems(root, label, kind)


def entity_problems(root: etree._Element, label: str) -> list[Problem]:
    """One problem per entity reference left in the text (``&name;``, which the hardened parser keeps
    unexpanded); an SSP writes characters or the five predefined entities, which are no such reference."""
    problems = []
    for entity in root.iter(etree.Entity):
        parent = entity.getparent()
        where = element_path(parent) if parent is not None else "/"
        problems.append(Problem(label, where, f"the entity reference {entity.text} (line {entity.sourceline}) is "
                                "not expanded: cosim reads no DTD entities (they may read other files or grow "
                                "without bound)", f"write the text itself in place of {entity.text}"))
    return problems


def schema_problems(root: etree._Element, label: str, kind: str) -> list[Problem]:
    """Every way ``root`` (an ssd, ssv or ssm document or inline element) breaks the official schema."""
    expected = {"ssd": tag("ssd", "SystemStructureDescription"), "ssv": tag("ssv", "ParameterSet"),
                "ssm": tag("ssm", "ParameterMapping")}[kind]
    if root.tag != expected:
        return [Problem(label, element_path(root), f"the root element is {short_name(root.tag)}, expected "
                        f"{short_name(expected)}", f"use an SSP {kind.upper()} file in the namespace {NS[kind]}")]
    schema = _schema(kind)
    document = etree.ElementTree(root) if root.getparent() is None else etree.ElementTree(_detached(root))
    try:
        if schema.validate(document):
            return []
    except etree.XMLSchemaValidateError as exc:  # lxml gives up on a node it cannot walk: the file's, not ours
        return [Problem(label, element_path(root), f"the SSP schema check cannot read the file: {exc}",
                        "write the file as plain SSP XML (elements, attributes and text only)")]
    by_line: dict[int, list] = {}
    for node in root.iter():
        if isinstance(node.tag, str):
            by_line.setdefault(node.sourceline, []).append(node)
    problems = []
    for entry in schema.error_log:
        message = _readable(entry.message)
        named = re.match(r"Element '([^']+)'", message)
        candidates = by_line.get(entry.line, [])
        # the element the message names, among those starting on its line
        node = next((n for n in candidates if named and short_name(n.tag) == named.group(1)),
                    candidates[0] if candidates else None)
        where = element_path(node) if node is not None else f"line {entry.line}"
        problems.append(Problem(label, where, f"breaks the SSP schema (line {entry.line}): {message}",
                                f"correct the element as the SSP standard's {SCHEMAS[kind]} requires"))
    return problems


def _detached(element: etree._Element) -> etree._Element:
    """A copy of an inline element as its own document (keeps source lines for messages)."""
    import copy

    return copy.deepcopy(element)
