"""C sources of the FMUs cosim ships, and the builder (:mod:`cosim.fmus.build`).

``from cosim.fmus.build import ensure_built; ensure_built("motor_gear_energy", 3)``
returns the path of a compiled FMU (built on first use, cached by source digest).

Offers: ``build.ensure_built`` (an FMU of ours, compiled on first use).
"""
