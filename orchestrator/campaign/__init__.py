"""Campaigns: run a study's scenarios × design cells × replicates, resumably, locally or on Dask.

Work is split into **chunks**: consecutive design cells of one scenario that
share every setting a batch cannot vary (e.g. the sampling time), up to
``batch`` runs. On the ``local`` engine a chunk is one batch: all its runs
are stepped together, the cells' factor levels given per replicate
(any numeric FMU parameter may differ per run). On the ``fmu`` engine a chunk's runs
are stepped one at a time through the FMUs, loaded once per worker process.
Chunks run in worker processes (``--workers``) or on a Dask distributed
cluster (``--scheduler``); only this process writes files.

Every run draws its random numbers from its own Philox streams, keyed by
(seed, scenario_key, cell, replicate, component, purpose) (docs/model.md, "Time and randomness"), and
a run's arithmetic does not depend on the batch it is stepped in, so
``runs.parquet`` is the same whatever the worker count, batch size,
scheduler or order of execution.

Campaign directory::

    study.toml          the resolved study (written first)
    chunks/ID.parquet   finished chunks, each written atomically
    manifest.json       each finished chunk's rows, cells, replicates and SHA-256, rewritten atomically after it
    timeseries/ID.parquet  per-step series (``--save-timeseries`` only)
    runs.parquet        all runs, sorted by scenario_key, cell, replicate

``--resume`` keeps only the chunks that verify: the manifest's checksum, and
the rows, cells and replicates the plan expects; a missing, damaged,
foreign or incomplete chunk is recomputed, with a line saying so. Without a
manifest (deleted by the user) every chunk is checked by its content alone.
"""

from sblsim.orchestrator.campaign.errors import CampaignError, CampaignInterrupted
from sblsim.orchestrator.campaign.executors import LOCAL_CLUSTER, close_client, connect
from sblsim.orchestrator.campaign.manifest import MANIFEST, read_manifest, verify_chunk
from sblsim.orchestrator.campaign.merge import collect
from sblsim.orchestrator.campaign.plan import DEFAULT_BATCH, Chunk, batch_key, cell_configs, plan
from sblsim.orchestrator.campaign.runner import CampaignRecord, run_campaign
from sblsim.orchestrator.campaign.study import Study, load_study
from sblsim.orchestrator.campaign.worker import run_chunk

__all__ = ["CampaignError", "CampaignInterrupted", "CampaignRecord", "Chunk", "DEFAULT_BATCH", "LOCAL_CLUSTER",
           "MANIFEST", "Study", "batch_key", "cell_configs", "close_client", "collect", "connect", "load_study", "plan",
           "read_manifest", "run_campaign", "run_chunk", "verify_chunk"]
