"""``python -m cosim``: the command line, as the ``cosim`` command."""

from cosim.cli.main import main

if __name__ == "__main__":
    raise SystemExit(main())
