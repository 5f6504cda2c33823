"""Motion ground truth export: MCAP for Foxglove, forecasting tables (the CTRV smoother: sot_apps.objects.smoother)."""
