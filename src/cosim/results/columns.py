"""The columns of a results table besides parameters and objectives: one definition for every writer and reader.

A row is ``point_id``, the parameters (arrays as ``target[i]``), the
objectives (flat), then :data:`TAIL_COLUMNS`.  ``status`` is one of
:data:`STATUSES`.  Column names become expression names by
:func:`cosim.spec.expressions.identifier`.
"""

STATUSES = ("ok", "failed", "timeout", "crashed")
TAIL_COLUMNS = ("status", "message", "run_time", "worker")
