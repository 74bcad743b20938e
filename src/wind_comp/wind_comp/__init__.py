"""Miller motion correction of buoy anemometer wind, the DVL current, and their live products."""
