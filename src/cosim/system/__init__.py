"""A system: the spec's names resolved into units, ports and connections, every misfit reported at once.
"""
