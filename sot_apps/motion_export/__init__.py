"""Motion ground truth export: kinematics (CTRV RTS smoother), MCAP for Foxglove, forecasting tables."""
