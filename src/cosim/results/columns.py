"""The columns of a results table besides parameters and objectives: one definition for every writer and reader.

A row is ``point_id``, the parameters (arrays as ``target[i]``), the
objectives (flat), then :data:`TAIL_COLUMNS`.  ``status`` is one of
:data:`STATUSES`.  Both are defined with the point's outcome that fills them
(:class:`cosim.execution.point_row.PointRow`, whose ``to_dict`` makes the row).
Column names become expression names by :func:`cosim.spec.expressions.identifier`.
"""

from cosim.execution.point_row import STATUSES, TAIL_COLUMNS  # noqa: F401  (the table's names for them)
