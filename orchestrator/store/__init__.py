"""A study's detections in an embedded columnar store: read once, streaming, in bounded memory (:mod:`.ingest`), and
read back a tag, a receiver or a time window at a time (:mod:`.query`); ``sblsim store``.

The store is a folder of Apache Parquet files (a dataset pyarrow, R's ``arrow``, DuckDB and Polars read as it is) and
one ``store.json``: no server, no engine of its own, nothing but files a user can copy, and no dependency sblsim
does not already have (pyarrow)."""
