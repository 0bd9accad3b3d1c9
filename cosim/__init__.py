"""The installed home of cosim's data and built-in units: ``cosim.models``, ``cosim.fmus``, ``cosim.specs``.

The repository keeps them as the top-level folders ``models/``, ``fmus/`` and ``specs/``; the wheel installs
them under this package (see ``[tool.setuptools]`` in pyproject.toml) so that nothing with a generic name such
as ``models`` lands in site-packages. Code imports them only as ``cosim.models`` / ``cosim.fmus``, and a spec's
``"python": "models.trajectory:TrajectoryGenerator"`` is resolved to ``cosim.models.trajectory``, so each module
is loaded once, under one name, whether cosim runs from a source checkout, an editable install or the wheel.
"""

from __future__ import annotations

from pathlib import Path

_here = Path(__file__).resolve().parent
if not (_here / "models").is_dir() and (_here.parent / "models" / "__init__.py").is_file() \
        and (_here.parent / "orchestrator").is_dir():
    # A source checkout: the subpackages are the repository's top-level folders beside this one.
    __path__.append(str(_here.parent))  # type: ignore[name-defined]  # noqa: F821
