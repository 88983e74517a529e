"""Views of the fleet model over HTTP: /metrics, the JSON API, the status page, and their security."""
