"""Simulated buoy sensors, truth, simulation clock, bag recorder and player."""
