"""The report of a wind-correction run, and of a current estimate: figures and tables in a folder.

- :mod:`buoy_processing.report.data`: everything a report shows, as plain arrays
  (:class:`ReportData`), gathered from a bag or a saved ``.npz`` file;
- :mod:`buoy_processing.report.attitude`: Euler angles, their 1σ and their errors;
- :mod:`buoy_processing.report.current`: the current of a bag (:class:`CurrentData`), its
  accuracy by window and against the window length;
- :mod:`buoy_processing.report.figures` and :mod:`buoy_processing.report.tables`: what is drawn
  and tabulated;
- :mod:`buoy_processing.report.folder`: all of it into one folder (:func:`write_report`). The
  ``wind_report`` command (:mod:`buoy_processing.wind_report`) runs it on a bag or a saved file.

The package imports nothing itself: the NetCDF writer takes the Euler angles of
:mod:`~buoy_processing.report.attitude` without loading matplotlib (some 0.6 s of every run).
"""
