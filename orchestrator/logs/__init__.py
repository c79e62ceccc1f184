"""A receiver's recorded log: read from a recorder's file or written from a run (:mod:`.receiver_log`,
docs/log-format.md), and replayed through a receiver as the master steps it in a run (:mod:`.replay`,
``sblsim replay LOG``)."""
