"""Writing a system out: as an SSP 2.0 archive (:mod:`.ssp`), a Python unit as an FMU (:mod:`.fmu`), a study's
surrogates as a C FMU (:mod:`.surrogate_fmu`).

Offers: ``ssp.export_ssp`` (a system as an SSP 2.0 archive), ``fmu.export_python_unit`` (a Python unit as an FMU),
``surrogate_fmu.export_surrogate_fmu`` (the numbers of DIR/surrogate/models.json as an FMI co-simulation FMU in C).
"""
