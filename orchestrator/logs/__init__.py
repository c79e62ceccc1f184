"""A receiver's recorded log: read from a recorder's file (:mod:`.receiver_log`, docs/log-format.md; the lowest range a
channel measures, :mod:`.range_floor`; a truth track, :mod:`.truth_track`) or written from a run (:mod:`.log_export`),
and replayed through a receiver as the master steps it in a run (:mod:`.replay`, ``sblsim replay LOG``: its
configuration, :mod:`.configuration`; which row each step shows, :mod:`.schedule`; the API's result,
:mod:`.replay_result`)."""
