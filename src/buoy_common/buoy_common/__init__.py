"""Shared infrastructure of the buoy wind suite."""
