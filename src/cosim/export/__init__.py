"""Writing a system out: as an SSP 2.0 archive (:mod:`.ssp`), a Python unit as an FMU (:mod:`.fmu`).

Offers: ``ssp.export_ssp`` (a system as an SSP 2.0 archive), ``fmu.export_python_unit`` (a Python unit as an FMU).
"""
