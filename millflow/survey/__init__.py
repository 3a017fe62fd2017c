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

A file is read with ``read_survey("examples/survey/survey.toml")``; the same survey can be
given as a dict on a flowsheet already loaded. Here a feed split into two streams, the
three solids flows measured (2 % relative SD) and the feed's sieve analysis:

Examples
--------
>>> from millflow.flowsheet import loads
>>> from millflow.survey import reconcile, survey_from_dict
>>> fs = loads('''
... grid = {top_um = 1000, bottom_um = 100, n = 4}
... [units]
... feed = {type = "feed", solids_tph = 100, psd = {form = "ggs", xmax_um = 1000, m = 0.8}}
... split = {type = "splitter", fractions = {a = 0.4, b = 0.6}}
... pa = {type = "product"}
... pb = {type = "product"}
... [streams]
... f = {from = "feed", to = "split"}
... a = {from = "split.a", to = "pa"}
... b = {from = "split.b", to = "pb"}
... ''')
>>> survey = survey_from_dict({
...     "errors": {"solids_rel_sd_pct": 2, "psd_sd_pct": 1},
...     "streams": {"f": {"solids_tph": 101.0, "psd": {"size_um": [500, 250], "passing_pct": [58, 33]}},
...                 "a": {"solids_tph": 39.0}, "b": {"solids_tph": 60.5}}}, flowsheet=fs)
>>> bal = reconcile(survey)
>>> f, a, b = (bal.solids(s)[0] for s in ("f", "a", "b"))  # reconciled [kg/s], with SD and observability
>>> abs(f - (a + b)) < 1e-12 * f  # the node balance holds exactly
True
>>> bal.chi_square["dof"], bal.chi_square["passed"], bal.gross_errors
(1, True, [])
"""
from millflow.survey.reader import ErrorModel, PSDMeasurement, StreamMeasurement, Survey, read_survey, survey_from_dict
from millflow.survey.reconcile import Balance, reconcile

__all__ = ["ErrorModel", "PSDMeasurement", "StreamMeasurement", "Survey", "read_survey", "survey_from_dict",
           "Balance", "reconcile"]
