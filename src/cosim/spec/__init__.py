"""The spec.json format: reading it (:mod:`.loader`), its JSON Schema (spec.schema.json), the design space
(:mod:`.design`) and the arithmetic of objectives and constraints (:mod:`.expressions`).

Offers: ``loader.load_spec`` and ``Spec``, ``design.DesignSpace``, ``expressions.evaluate_expressions``.
"""
