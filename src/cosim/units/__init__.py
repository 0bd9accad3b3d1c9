"""Units: the protocol every unit obeys, the registry of unit kinds, and the kinds cosim ships.

Offers: ``protocol.UnitType``, ``Unit`` and ``Variable`` (the unit protocol), ``kind.UnitKind``,
``registry.register_unit_kind``, ``python.unit.PythonUnit``; the built-in kinds ``fmu``, ``python``, ``player``,
``connectors``.
"""
