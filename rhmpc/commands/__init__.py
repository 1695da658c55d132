"""Command modules of the `rhmpc` console script, one module per subcommand."""
