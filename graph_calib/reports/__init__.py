"""Reports: self-contained HTML pages with embedded figures, built from results (never inside a solver).

- :mod:`graph_calib.reports.html`: generic helpers (tables, embedded PNG figures, the page frame);
- :mod:`graph_calib.reports.campaign_report`: the report of ``graph-calib campaign``.

Figures use matplotlib's non-interactive ``Agg`` backend.
"""
