"""The ``bearcat`` command: the parser (``main``), one module per subcommand,
and the argument, output, progress and file-writing helpers they share."""
