"""What every system connector of an SSP carries, for naming connectors in a spec (``Root.sub.connector``)."""

from __future__ import annotations

from cosim.ssp.connections import Flow
from cosim.ssp.reading import Reading


def connector_signals(reading: Reading, flow: Flow, system_values: dict, unit_names: dict,
                      root_name: str) -> dict[str, tuple]:
    """What every system connector carries, by its name with and without the root system's name.

    A connector fed (through a chain) by a component output carries factor x that output + offset (the
    chain's conversions and transformations): ("port", 'unit.port', factor, offset); one holding a bound value
    carries that value: ("value", v).  A connector whose chain cannot be followed (a loop, units that do not
    convert) carries nothing known and is left out: this is for naming connectors in a spec, the SSP was
    checked already.
    """
    signals: dict[str, tuple] = {}
    problems = list(reading.problems)
    for node in reading.nodes.values():
        if node.kind != "system":
            continue
        for name in node.connectors:
            end = (node.path, name)
            carried: tuple | None = None
            if end in flow.into:
                chain = flow.chain(end)
                start = chain[0].start
                if reading.nodes[start[0]].kind == "component" and start[0] in unit_names:
                    factor, offset = flow.compose(chain, flow.unit_of(start))
                    carried = ("port", f"{unit_names[start[0]]}.{start[1]}", factor, offset)
                elif start in system_values:
                    carried = ("value", system_values[start][2])
            elif end in system_values:
                carried = ("value", system_values[end][2])
            if carried is not None:
                signals[".".join((root_name, *node.path, name))] = carried
                signals.setdefault(".".join((*node.path, name)), carried)
    reading.problems[:] = problems  # a chain only named here (no FMU input at its end) reports nothing new
    return signals
