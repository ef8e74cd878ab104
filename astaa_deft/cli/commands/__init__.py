"""One module per CLI command; cli.py only wires arguments to these."""
