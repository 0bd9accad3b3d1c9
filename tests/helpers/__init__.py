"""What the test files share: paths (paths.py), tool and unit helpers (tools.py), Dask processes
(sweep_fixtures.py), SSPs (ssp_fixtures.py), the native-kernel twin (kernel_twins.py), independent
reference computations (reference.py), test units (units_for_tests.py, units_for_cluster.py).

Plain functions and constants, imported by name (``from tests.helpers.paths import REPO``); the pytest
fixtures are in tests/conftest.py."""
