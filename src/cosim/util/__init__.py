"""Leaf helpers every layer may use: safe archives, file digests, input limits, units of measure, strict JSON.

Nothing here imports another part of cosim except :mod:`cosim.errors`.

Offers: ``archive.safe_extract``, ``digest.file_digest``, ``limits.limit``, ``quantities.conversion``,
``strict_json.read_spec_json``.
"""
