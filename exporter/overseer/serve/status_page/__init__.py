"""The fleet status page, served by the exporter itself (no build step, no CDN)."""
