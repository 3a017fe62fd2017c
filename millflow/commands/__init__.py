"""Sub-commands of the `millflow` command line, one module each (see millflow.cli).

:data:`COMMANDS` maps each sub-command to its module and its one-line help: the command
line imports only the module of the command it runs (a command module may import
scipy, xarray, rtd or matplotlib at its top), and lists the others from this table.
A new command is a new module with ``add_parser(subparsers)`` and a line here
(tests/millflow/test_startup.py checks that the two agree).
"""

#: Sub-command name -> (module of millflow.commands, the help line its add_parser registers).
COMMANDS = {
    "balance": ("balance", "mass-balance (reconcile) a plant survey"),
    "bench": ("bench", "run a benchmark suite (work-precision tables, timings)"),
    "compare": ("compare", "solve two flowsheets and compare the streams they share"),
    "diagnose": ("diagnose", "rank candidate kinetics (linear, slowing-down, cushioning, aggregation, RTDs) "
                             "on a fit config's data"),
    "falsify": ("falsify", "measure how model error falsifies fitted breakage kinetics"),
    "fit": ("fit", "fit breakage (and classification) parameters to PSD data, or a circuit to a survey"),
    "fit-rtd": ("fit_rtd", "fit an RTD model to tracer data"),
    "run": ("run", "solve a flowsheet file (TOML) and write its results"),
    "scaleup": ("scaleup", "predict a plant mill/circuit from a lab fit, with uncertainty"),
    "sweep": ("sweep", "solve a flowsheet over a grid or sample of its inputs (Dask)"),
}

#: The commands that use dask (a LocalCluster, a scheduler). In the process of any other
#: command line, millflow.cli tells xarray that dask is absent: xarray imports dask.array
#: (0.5-1 s) the first time it builds or encodes a variable, only to learn that a numpy
#: array is not a dask array.
USES_DASK = frozenset({"sweep", "bench"})
