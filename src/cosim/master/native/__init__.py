"""The native stepping kernel: fixed-step communication loops of FMI co-simulation FMUs run in C
(:mod:`.library` builds and loads it, :mod:`.tables` lays the system out for it, :mod:`.algorithm` is the
:class:`~cosim.master.contract.MasterAlgorithm` that drives it)."""
