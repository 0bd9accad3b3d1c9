"""The ``cosim`` command line: one module per group of subcommands; the only place exit codes are decided.

Offers: ``main.main`` (the command line), ``exit_codes.exit_code`` (the one mapping of errors to exit codes).
"""
