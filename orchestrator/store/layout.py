"""A store's layout, the names every module of :mod:`sblsim.orchestrator.store` and ``sblsim store`` share (no
imports: the command line's start reads it)."""

#: The file that marks a store's folder and describes it, written last (:mod:`.ingest`).
STORE_FILE = "store.json"
#: The value of that description's ``marker`` key.
MARKER = "sblsim detections store"
#: The layout's version (the description's ``layout``).
LAYOUT = 1

__all__ = ["LAYOUT", "MARKER", "STORE_FILE"]
