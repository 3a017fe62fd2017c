"""Plant surveys: reading them, mass balancing (data reconciliation) and fitting a circuit to them.

A survey samples most streams of a circuit (solids flow, water or % solids, a sieve
analysis), each with a standard deviation, on the topology of a flowsheet file. The
measurements never close the balances; :func:`reconcile` finds the smallest weighted
adjustments that do (node balances of every size class, of total solids and of water
held exactly), with the statistics a metallurgist acts on: chi-square test of the
weighted sum of squares, normalised adjustments naming gross-error candidates,
derived unmeasured flows and circulating loads with standard deviations, and which
quantities the data leave undetermined. :func:`fit_circuit` then fits named flowsheet
parameters to all streams of the reconciled survey at once.

>>> from millflow.survey import read_survey, reconcile   # doctest: +SKIP
>>> bal = reconcile(read_survey("examples/survey/survey.toml"))   # doctest: +SKIP
>>> bal.chi_square["p_value"]   # doctest: +SKIP
"""
from millflow.survey.reader import ErrorModel, PSDMeasurement, StreamMeasurement, Survey, read_survey, survey_from_dict
from millflow.survey.reconcile import Balance, reconcile

__all__ = ["ErrorModel", "PSDMeasurement", "StreamMeasurement", "Survey", "read_survey", "survey_from_dict",
           "Balance", "reconcile"]
