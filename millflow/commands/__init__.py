"""Sub-commands of the `millflow` command line, one module each (see millflow.cli)."""
