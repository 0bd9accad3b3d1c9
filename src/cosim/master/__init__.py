"""Master algorithms and observers: how the units of a system are stepped together, and what watches a run.

This layer knows units and the links between their ports; it knows nothing of spec.json or SSP files.
"""
