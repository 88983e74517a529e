"""The fleet's event history: transitions detected (`detector`), stored in SQLite (`store`), served.

`events` is the record, `query` the filters of /api/v1/events, `metrics` the store's own metrics, and
`service` ties them to a fleet model for the exporter.
"""
