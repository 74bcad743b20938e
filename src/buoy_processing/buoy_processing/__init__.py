"""The offline application: bags and archives processed, NetCDF files, reports and calibrations."""
