"""A results folder on disk: the rows as they come (:mod:`.store`), the lock, the columns, the unit checksums.
"""
