"""The detection formats sblsim reads (:func:`~sblsim.orchestrator.readers.detections.read_detections`), by the names a
command's ``--format`` takes; light, so that the command line lists them without loading a reader."""

from __future__ import annotations

#: The detection formats: the YAPS table, Innovasea's VUE and Fathom exports, the GLATOS and OTN networks' extracts,
#: actel's own detections and Thelma Biotel's exports.
FORMATS = ("yaps", "vue", "fathom", "glatos", "otn", "actel", "thelma")

__all__ = ["FORMATS"]
