"""Evaluation in one place: tracker (``tracker``), motion export (``motion``), flow (``flow``), LiDAR realism
(``realism``). Pure functions with configs as data; ``bench`` adds argument parsing, timing and tables, ``report``
renders the results."""

# PandaSet 002's 9 moving vehicles that LiDAR-SOT's criteria keep (the tuning set: figures on them are "tuned on").
DEV_TRACKS = ("20d13d1d", "8ac00bad", "0d238564", "f0b32b02", "91aa5b5c", "71a404f3", "8febbea0", "1a46fa13",
              "b09e1c68")
