"""Dual-antenna GNSS/SINS error-state Kalman filter for a buoy, live and from bags."""
