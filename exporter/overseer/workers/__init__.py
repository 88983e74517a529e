"""Ingest workers: processes that each follow their own robots, served as one fleet by the exporter.

`process` is what runs in a worker; `pool` starts, asks and restarts them; `merge` joins their answers;
`view` serves the joined fleet to the endpoint; `metrics` tells how the workers fare.
"""
