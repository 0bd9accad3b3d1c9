"""Writing a system out: as an SSP 2.0 archive (:mod:`.ssp`), a Python unit as an FMU (:mod:`.fmu`).
"""
