"""Reports a person opens and shares: a self-contained ``report.html`` (tables, SVG plots,
the flowsheet drawing) and ``results.xlsx`` (stream table and size-by-stream balance).

- :mod:`millflow.report.layout`: where units, streams and labels of a flowsheet drawing go.
- :mod:`millflow.report.textsize`: how wide a line of the drawing's text is; long names broken.
- :mod:`millflow.report.html`: the page builder (tables, SVG line plots, flowsheet SVG).
- :mod:`millflow.report.flowsheet`: the report of a solved flowsheet from its summary.
- :mod:`millflow.report.balance`: the report of a reconciled plant survey.
- :mod:`millflow.report.studies`: the reports of a fit, a scale-up, a comparison and a sweep.
- :mod:`millflow.report.excel`: the workbook (needs openpyxl: ``pip install millflow[report]``).
"""
from millflow.report.flowsheet import flowsheet_report, partition_curves, write_report

__all__ = ["flowsheet_report", "partition_curves", "write_report"]
