"""Monte Carlo experiments on one scenario's replicates: several receivers or positioning systems side by side
(:mod:`.compare`, ``sblsim compare``) and each error source's share of the position error (:mod:`.budget`,
``sblsim budget``; its sources and their switches :mod:`.error_sources`, its outputs :mod:`.budget_outputs`).
A factorial study over scenarios is a campaign's (:mod:`sblsim.orchestrator.campaign`)."""
