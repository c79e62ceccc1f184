"""A telemetry study as its people run it: the receivers' deployments (in latitude and longitude, with dates), the
receivers' own detection exports, a tag sheet, every tag tracked in one call, the tracks in latitude, longitude and
UTC (``sblsim track``, :func:`sblsim.track`)."""
