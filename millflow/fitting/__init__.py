"""Parameter estimation for population-balance models of milling (Principles II-VI).

Read PSD long tables (:mod:`.data`), describe and compile a forward model with shared
parameters and eq. 10 power laws (:mod:`.models`), estimate globally with eq. 9
statistics (:mod:`.estimate`, :mod:`.statistics`), predict held-out conditions
(:mod:`.validate`), write tables and plots (:mod:`.report`); :mod:`.config` reads the
TOML file of ``millflow fit``. See docs/fitting.md.
"""
from millflow.fitting.data import PSDData, psd_data_from_frames, read_process_table, read_psd_table, read_sprite_folder
from millflow.fitting.estimate import FitResult, compare_models, fit
from millflow.fitting.models import ForwardModel, ModelSpec, Parameter, default_parameters
from millflow.fitting.statistics import f_test, information_criteria, parameter_statistics
from millflow.fitting.validate import condition_rmse, leave_out, nested_leave_out

__all__ = [
    "PSDData", "psd_data_from_frames", "read_psd_table", "read_process_table", "read_sprite_folder",
    "ModelSpec", "ForwardModel", "Parameter", "default_parameters",
    "fit", "compare_models", "FitResult", "parameter_statistics", "information_criteria", "f_test",
    "leave_out", "nested_leave_out", "condition_rmse",
]
