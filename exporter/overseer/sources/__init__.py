"""Transports: each subscribes to robots' diagnostics and hands raw payloads to the fleet model."""
