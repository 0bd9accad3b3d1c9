"""A results folder on disk: the rows as they come (:mod:`.store`), the lock, the columns, the unit checksums.

Offers: ``store.ResultsStore`` (a results folder's rows), ``lock.FolderLock``, ``columns.STATUSES``,
``folder.default_folder``.
"""
