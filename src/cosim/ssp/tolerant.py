"""Forms popular tools write although the SSP schema says otherwise, read as what they mean.

:func:`tolerated` returns a corrected copy of a parsed SSD, .ssv or .ssm and one
note per correction, naming the file, the element and the standard's form
(keyed by the kind of correction, so that the reader writes many alike as one
line with a count, see :mod:`.notes`):

- an ``ssv:ParameterSet`` or ``ssm:ParameterMapping`` without ``version``
  (OMSimulator 3 writes its inline .ssm so): read as the document's version;
- two ``ssd:ParameterBindings`` on one element (OMSimulator 3 writes inline
  values and .ssv references as siblings): merged into the first, in document
  order, so later bindings still win;
- the children of an ``ssd:System``, ``ssd:Component`` or the root in another
  order than the schema's (OMSimulator 2 put ``ssd:Annotations`` first, Dymola
  ``ssd:Connectors`` after other children): put in the schema's order.

The reader uses the copy only when the original breaks the schema and the copy
does not, so that problems always point at the user's own file otherwise.
Element source lines are kept (``copy.deepcopy``).
"""

from __future__ import annotations

import copy
from typing import Any

from cosim.ssp.notes import Note
from cosim.ssp.xml import NS, element_path, short_name, tag

_ELEMENT = ["ssd:Connectors", "ssd:ElementGeometry", "ssd:ParameterBindings", "ssc:MetaData", "ssc:Signature"]
_ORDER = {
    tag("ssd", "SystemStructureDescription"): ["ssd:System", "ssd:Enumerations", "ssd:Units", "ssd:DefaultExperiment",
                                               "ssc:MetaData", "ssc:Signature", "ssd:Annotations"],
    tag("ssd", "Component"): [*_ELEMENT, "ssd:Annotations"],
    tag("ssd", "SignalDictionaryReference"): [*_ELEMENT, "ssd:Annotations"],
    tag("ssd", "System"): [*_ELEMENT, "ssd:Elements", "ssd:Connections", "ssd:SignalDictionaries",
                           "ssd:SystemGeometry", "ssd:GraphicalElements", "ssd:Annotations"],
}
_VERSIONED = (tag("ssv", "ParameterSet"), tag("ssm", "ParameterMapping"))
_STANDARD_ORDER = {
    tag("ssd", "System"): "Connectors, ElementGeometry, ParameterBindings, MetaData, Signature, Elements, "
                          "Connections, SignalDictionaries, SystemGeometry, GraphicalElements, Annotations",
    tag("ssd", "Component"): "Connectors, ElementGeometry, ParameterBindings, MetaData, Signature, Annotations",
    tag("ssd", "SignalDictionaryReference"): "Connectors, ElementGeometry, ParameterBindings, MetaData, Signature, "
                                             "Annotations",
    tag("ssd", "SystemStructureDescription"): "System, Enumerations, Units, DefaultExperiment, MetaData, "
                                              "Signature, Annotations",
}


def _clark(short: str) -> str:
    prefix, _, local = short.partition(":")
    return f"{{{NS[prefix]}}}{local}"


def tolerated(root: Any, label: str) -> tuple[Any, list[Note]]:
    """A copy of ``root`` with the tolerated forms corrected, and one note per correction; ``(root, [])`` when
    there is nothing to correct."""
    fixed = copy.deepcopy(root)
    notes: list[Note] = []
    version = root.get("version") if root.get("version") in ("1.0", "2.0") else "2.0"
    # notes name the user's element: an inline element's copy has lost its ancestors
    for element, original in list(zip(fixed.iter(), root.iter())):  # a list: the loop moves children around
        if not isinstance(element.tag, str):
            continue
        found = []
        if element.tag in _VERSIONED and element.get("version") is None:
            element.set("version", version)
            found.append(f"has no 'version' (SSP requires version=\"1.0\" or \"2.0\"); read as version {version}")
        if element.tag in _ORDER:
            found.extend(_merge_bindings(element))
            found.extend(_reorder(element))
        where = element_path(original) if found else ""  # only then: a path costs a walk over the siblings
        notes.extend(Note(("tolerated", label, what), f"{label}: {where} {what}", where,
                          f"more elements of {label} likewise") for what in found)
    return (fixed, notes) if notes else (root, [])


def _merge_bindings(element: Any) -> list[str]:
    containers = [c for c in element if isinstance(c.tag, str) and c.tag == tag("ssd", "ParameterBindings")]
    if len(containers) < 2:
        return []
    first = containers[0]
    for other in containers[1:]:
        for binding in list(other):
            first.append(binding)
        element.remove(other)
    return [(f"has {len(containers)} ssd:ParameterBindings; SSP allows one (with several ssd:ParameterBinding "
             "inside): read as one, in document order")]


def _reorder(element: Any) -> list[str]:
    rank = {_clark(name): i for i, name in enumerate(_ORDER[element.tag])}
    children = list(element)
    keyed, last = [], -1
    for position, child in enumerate(children):
        if isinstance(child.tag, str):
            last = rank.get(child.tag, last)  # an element the schema does not name keeps its neighbour's place
        keyed.append((last, position, child))  # comments travel with the element before them
    ordered = [child for _, _, child in sorted(keyed, key=lambda k: (k[0], k[1]))]
    if ordered == children:
        return []
    first_wrong = next(i for i, (a, b) in enumerate(zip(children, ordered)) if a is not b)
    moved = next(c for c in children[first_wrong:] if isinstance(c.tag, str))
    before = next(c for c in ordered[first_wrong:] if isinstance(c.tag, str))
    for child in children:
        element.remove(child)
    element.extend(ordered)
    return [(f"has its children in an order the schema does not give ({short_name(moved.tag)} before {short_name(before.tag)}); "
             f"SSP 2.0 expects {_STANDARD_ORDER[element.tag]}: read as if so")]
