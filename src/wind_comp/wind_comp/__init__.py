"""Miller motion correction of buoy anemometer wind, the current from a DVL, and their live products."""
