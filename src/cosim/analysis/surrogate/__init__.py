"""Surrogate models of a study's objectives, with their prognosis quality (``cosim surrogate``).

- :mod:`.models`: the fitted surrogates as plain numbers (Gaussian process, polynomial), evaluated with numpy;
- :mod:`.fit`: fitting them with scikit-learn, the k-fold coefficient of prognosis Q², ``auto`` choosing by it;
- :mod:`.ranking`: the parameters ranked by the Sobol indices of a surrogate (SALib);
- :mod:`.failures`: a classifier of where designs fail;
- :mod:`.study`: all of it for a results table, stored in ``DIR/surrogate/`` and read back.
"""

from cosim.analysis.surrogate.study import SurrogateSet, fit_table, read, surrogate_folder, write

__all__ = ["SurrogateSet", "fit_table", "read", "surrogate_folder", "write"]
