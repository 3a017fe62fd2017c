"""Scale-up from a lab fit to a plant mill, with the fit's uncertainty carried along.

Plain functions (power, scaling, hold-up) in :mod:`.power` and :mod:`.scaling`;
:mod:`.fitted` reads a ``millflow fit --json`` result; :mod:`.plant` describes mills by
dimensions and the circuit they work in; :mod:`.predict` binds them; :mod:`.uncertainty`
propagates eq. 9's covariance; :mod:`.api` returns the result object.
"""
from millflow.scaleup.api import ScaleupResult, predict_plant
from millflow.scaleup.fitted import FittedBreakage, fit_from_dict, load_fit
from millflow.scaleup.plant import Circuit, MillDesign
from millflow.scaleup.power import (austin_power, ball_charge_mass, bond_rowland_power, charge_arm,
                                    critical_speed, gross_power, hogg_fuerstenau_power, mill_power)
from millflow.scaleup.predict import ScaleUp
from millflow.scaleup.scaling import austin_factors, herbst_fuerstenau_rates, specific_rates
from millflow.scaleup.uncertainty import delta_method, monte_carlo

__all__ = ["Circuit", "FittedBreakage", "MillDesign", "ScaleUp", "ScaleupResult", "austin_factors",
           "austin_power", "ball_charge_mass", "bond_rowland_power", "charge_arm", "critical_speed",
           "delta_method", "fit_from_dict", "gross_power", "herbst_fuerstenau_rates", "hogg_fuerstenau_power",
           "load_fit",
           "mill_power", "monte_carlo", "predict_plant", "specific_rates"]
