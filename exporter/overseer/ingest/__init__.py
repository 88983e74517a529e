"""The ingest: from one topic's raw payloads to the fleet model, decoding only what changed."""
