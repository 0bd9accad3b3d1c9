"""Understanding a sweep: results tables, Pareto fronts, point-cloud plots, the report and the explorer.

- :mod:`.table`: load a results table (+ optional sweep metadata), units, labels, ``--where`` filters.
- :mod:`.pareto`: non-dominated rows (ties kept, NaN rows excluded).
- :mod:`.plots`: 2-D/3-D scatter clouds with greyed points and colour bars.
- :mod:`.sensitivity`: how strongly each parameter drives each objective.
- :mod:`.report`: one self-contained HTML page.
- :mod:`.rerun`: re-run one design point of a table with full traces.
- :mod:`.explorer`: the interactive Tk window (state in a plain class, thin view).

Offers: ``table.load_results`` (a ``ResultsTable``), ``pareto.pareto_mask``, ``hypervolume.hypervolume``,
``report.write_report``, ``rerun.rerun``, ``decision.Decision``; ``room/`` (the web decision room).
"""

from cosim.analysis.pareto import pareto_mask
from cosim.analysis.table import AnalysisError, ResultsTable, load_results

__all__ = ["AnalysisError", "ResultsTable", "load_results", "pareto_mask"]
