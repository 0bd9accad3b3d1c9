"""FMU units: the model description (:mod:`.description`), FMI 2.0 and 3.0 co-simulation instances
(:mod:`.fmi2`, :mod:`.fmi3`) and Model Exchange FMUs integrated by cosim (:mod:`.model_exchange`).
"""
