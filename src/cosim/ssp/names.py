"""The one renaming of SSP names into cosim names.

SSP allows any text as the name of a system, component or system connector (``DC-Motor``, ``sub system``,
``Motor.1``, ``Drehzahl_ü``); a cosim unit or port name is ``[A-Za-z_][A-Za-z0-9_]*`` parts joined by dots.
:func:`cosim_name` maps one to the other the same way everywhere (units, ``connectors`` units, record, traces,
objectives, design parameters, ``--set``): in each dot-separated part every character other than an ASCII
letter, digit or ``_`` becomes ``_``, and a part that would start with a digit gets a leading ``_``.  A spec may name things either way; :func:`rename_prefix` turns the SSP's spelling into cosim's.
"""

from __future__ import annotations

import re
from typing import Iterable, Mapping

_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_OTHER = re.compile(r"[^A-Za-z0-9_]")


def cosim_part(name: str) -> str:
    """One part of a name (no dots kept): ``'DC-Motor'`` -> ``'DC_Motor'``, ``'1st'`` -> ``'_1st'``."""
    if not name or _NAME_RE.match(name):  # '' stays '' (a root system without a name)
        return name
    part = _OTHER.sub("_", name)
    return part if part[:1].isalpha() or part[:1] == "_" else f"_{part}"


def cosim_name(name: str) -> str:
    """A dotted SSP name with each part made a cosim name (dots kept: a component exported from a flattened
    system may be called ``motor.shaft``)."""
    return ".".join(cosim_part(p) for p in name.split("."))


def cosim_path(path: Iterable[str]) -> str:
    """The cosim name of an element path (``('S u-T', 'motor')`` -> ``'S_u_T.motor'``)."""
    return ".".join(cosim_name(p) for p in path)


def rename_prefix(text: str, renamed: Mapping[str, str]) -> str:
    """``text`` ('DC-Motor.SuT.phiB', a unit's 'S u-T.motor.y') with its longest prefix that is an SSP name in
    ``renamed`` (SSP name -> cosim name) written as cosim names it; ``text`` itself when none is."""
    cut = len(text)
    while cut > 0:
        head = text[:cut]
        if head in renamed and (cut == len(text) or text[cut] == "."):
            return renamed[head] + text[cut:]
        cut = text.rfind(".", 0, cut)
    return text
