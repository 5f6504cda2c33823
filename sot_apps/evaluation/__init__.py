"""Evaluation in one place: tracker (``tracker``), motion export (``motion``), flow (``flow``), LiDAR realism
(``realism``). Pure functions with configs as data; ``bench`` adds argument parsing, timing and tables, ``report``
renders the results."""
