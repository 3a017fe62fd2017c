"""Readers of a flowsheet document's parts, one module per job.

:mod:`millflow.flowsheet.io` puts them together (``load``, ``loads``, ``from_dict``):
``tables`` (a TOML table handing out plain and unit-suffixed values, plausible ranges,
one-line errors), ``grid`` (the size grid), ``feeds`` (feed PSDs and feed water),
``materials`` (rates, breakage functions, fitted materials), ``transport`` (a mill's
transport table, tracer fits, series), ``mills`` (a mill unit: material, transport,
residence time or hold-up, dimensions, power, classification, kinetics) and
``classifiers`` (efficiency curves, predicted hydrocyclones, classifier water).
Every unit-suffixed key is read through :func:`millflow.inputs.quantity`.
"""
