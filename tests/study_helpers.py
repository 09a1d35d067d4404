"""Shared pieces of the study tests: a small study and a LocalCluster client."""
from __future__ import annotations

from typing import Iterator

#: 2 records x 3 gaps of the default scene, 3 s each
SMALL = """
name = "small"
scene = "default"
[set]
stop_time = 3.0          # s: El Centro makes the buildings pound within 3 s at these gaps
[vary]
"ground.record" = ["elcentro1940", "sanfernando1971"]
"pounding.gap" = [0.0, 0.01, 0.02]
"""


def local_client(n_workers: int, silence_logs: int) -> Iterator:
    """A Dask client on a LocalCluster of ``n_workers`` single-threaded worker processes (for a
    module-scoped fixture: yields the client, closes both after)."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None,
                           scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}, silence_logs=silence_logs)
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()
