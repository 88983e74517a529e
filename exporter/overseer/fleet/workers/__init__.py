"""Ingest workers: processes that each follow their own robots, joined into one fleet by `PooledFleet`.

`process` is what runs in a worker (a `LocalFleet` of its robots, answering the exporter's requests);
`pool` starts, asks and restarts them (`launch` starts one process, `shared_counts` is the memory they
count their robots in); `merge` joins their answers; `metrics` tells how the workers fare.
"""
