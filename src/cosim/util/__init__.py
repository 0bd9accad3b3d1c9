"""Leaf helpers every layer may use: safe archives, file digests, input limits, units of measure, strict JSON.

Nothing here imports another part of cosim except :mod:`cosim.errors`.
"""
