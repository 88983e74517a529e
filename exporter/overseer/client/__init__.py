"""The exporter's HTTP API as a library: `exporter.ExporterClient` over `http`'s one-request transport.

Nothing is imported here: `check_ros_diagnostics` imports only the modules it needs.
"""
