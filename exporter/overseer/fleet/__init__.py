"""The fleet as every output reads it: one interface (`interface.Fleet`), two implementations.

`local.LocalFleet` holds one model in this process (the builder of model, sources, transition watch,
expiry and renderer); `pooled.PooledFleet` joins ingest worker processes (`workers/`), each running a
`LocalFleet` of its own robots. What both hand out is rendered here too: the exposition's per-robot
lines (`exposition`), the JSON API's documents (`documents`).
"""
