"""The ``cosim`` command line: one module per group of subcommands; the only place exit codes are decided.
"""
