"""Miller motion correction of buoy anemometer wind, wind products and reports."""
