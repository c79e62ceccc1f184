"""``sblsim sync``'s work: the raw detections read (:mod:`~sblsim.orchestrator.readers.detections`), the receivers'
clocks synchronised from the sync tags (:mod:`~sblsim.orchestrator.sync.run`, on the model of
:mod:`sblsim.models.sync`) and its files and figures (:mod:`~sblsim.orchestrator.sync.outputs`); and ``sblsim toa``'s:
a tag's times-of-arrival matrix on the synchronised clocks (:mod:`~sblsim.orchestrator.sync.toa`)."""
