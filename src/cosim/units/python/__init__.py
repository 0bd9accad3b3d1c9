"""Units written in Python (:mod:`.unit`), their vectorised twins (:mod:`.batch`), the data files they
read and the guarded import of their modules.
"""
