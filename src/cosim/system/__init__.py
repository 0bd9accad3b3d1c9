"""A system: the spec's names resolved into units, ports and connections, every misfit reported at once.

Offers: ``builder.build_system`` and ``System`` (a checked system), ``validate.check_spec`` (every problem at once).
"""
