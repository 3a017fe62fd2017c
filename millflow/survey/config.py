"""A ``millflow fit`` configuration that fits a circuit to a survey (docs/survey.md).

Two forms: a fit config with a ``[survey]`` table, or the survey file itself with its
``[fit]`` table; :func:`survey_fit_config` reads either (or says the file is not one).
"""
from __future__ import annotations

from dataclasses import dataclass

from millflow.errors import InputError, MillflowError
from millflow.survey.fit import _get, read_fit_table

__all__ = ["SurveyFitConfig", "survey_fit_config"]


@dataclass
class SurveyFitConfig:
    """A ``millflow fit`` configuration that fits a circuit to a survey (see :func:`survey_fit_config`)."""

    path: str
    survey: object
    fit: dict          # {"names", "bounds", "starts", "global_search", "leave_one_out"}
    out_dir: str | None
    plots: bool
    seed: int = 0


def survey_fit_config(path) -> SurveyFitConfig | None:
    """The survey fit a ``millflow fit`` config asks for, or None when it is not a survey fit.

    Two forms: a fit config with a ``[survey]`` table (``file`` = the survey, relative to the
    config; the circuit parameters as ``[params."dotted.flowsheet.key"]`` with ``min`` and
    ``max``; ``[optimizer]`` ``global``, ``starts``, ``seed``; ``[validation]``
    ``leave_one_stream_out``; ``[output]`` ``dir``, ``plots``), or the survey file itself,
    whose ``[fit]`` table names the parameters.
    """
    from pathlib import Path

    from millflow.inputs import check_keys, read_toml
    from millflow.survey.reader import read_survey, survey_from_dict

    p = Path(path)
    if not p.is_file():
        return None  # the ordinary fit config reader says so
    data = read_toml(p, "config")
    if "survey" not in data and not ("flowsheet" in data and "streams" in data):
        return None
    where = f"{p}"
    if "survey" not in data:  # the survey file itself
        survey = read_survey(p)
        if not survey.fit:
            raise InputError(f"{where}: a survey fitted by millflow fit needs a [fit] table naming the parameters "
                             "(e.g. [fit.parameters] \"units.cyclones.d50c_um\" = {min = 50, max = 300})")
        return SurveyFitConfig(str(p), survey, survey.fit, None, True)
    check_keys(data, {"survey", "params", "optimizer", "validation", "output"}, where)
    s = data["survey"]
    if not isinstance(s, dict):
        raise InputError(f"{where} [survey]: expected a table with file = \"survey.toml\"")
    check_keys(s, {"file"}, f"{where} [survey]")
    name = s.get("file")
    if not isinstance(name, str) or not name:
        raise InputError(f"{where} [survey]: missing key 'file' (the survey file, relative to the config)")
    sp = Path(name) if Path(name).is_absolute() else p.resolve().parent / name
    if not sp.is_file():
        raise InputError(f"{where} [survey] file = {name!r}: no such file ({sp})")
    raw = read_toml(sp, "survey file")
    raw.pop("fit", None)  # the config's parameters, not the survey's
    try:
        survey = survey_from_dict(raw, source=str(sp))
    except MillflowError as exc:
        raise type(exc)(f"{sp}: {exc}") from exc
    opt = data.get("optimizer", {})
    val = data.get("validation", {})
    out = data.get("output", {})
    for key, t, keys in (("optimizer", opt, {"global", "starts", "seed"}),
                         ("validation", val, {"leave_one_stream_out"}), ("output", out, {"dir", "plots"})):
        if not isinstance(t, dict):
            raise InputError(f"{where} [{key}]: expected a table")
        check_keys(t, keys, f"{where} [{key}]")
    if "params" not in data:
        raise InputError(f"{where}: missing [params.\"dotted.flowsheet.key\"] tables (min, max) naming the "
                         "circuit parameters to fit")
    table = {"parameters": data["params"], "starts": opt.get("starts", 3),
             "global_search": opt.get("global", False),
             "leave_one_out": val.get("leave_one_stream_out", True)}
    names, bounds, options = read_fit_table(table, f"{where} [params]")
    doc = survey.flowsheet.meta.get("document", {})
    for n in names:
        try:
            _get(doc, n)
        except MillflowError as exc:
            raise InputError(f"{where} [params.\"{n}\"]: {exc}") from exc
    seed = opt.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise InputError(f"{where} [optimizer] seed = {seed!r}: expected a whole number")
    plots = out.get("plots", True)
    if not isinstance(plots, bool):
        raise InputError(f"{where} [output] plots = {plots!r}: expected true or false")
    d = out.get("dir")
    if d is not None and not isinstance(d, str):
        raise InputError(f"{where} [output] dir = {d!r}: expected a folder name")
    out_dir = None if d is None else str(Path(d).absolute())  # the current folder, as --out (docs/cli.md)
    return SurveyFitConfig(str(p), survey, {"names": names, "bounds": bounds, **options}, out_dir, plots, seed)
