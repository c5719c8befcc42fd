"""The ``abu`` command line: one parser (``main``), one module per group of commands."""
