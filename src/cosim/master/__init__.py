"""Master algorithms and observers: how the units of a system are stepped together, and what watches a run.

This layer knows units and the links between their ports; it knows nothing of spec.json or SSP files.

Offers: ``contract.MasterAlgorithm``, ``SystemView`` and ``StepGrid`` (the one contract),
``registry.make_algorithm`` and ``ALGORITHMS``, ``observers.Observer`` and ``StopCondition``.
"""
