"""Maintenance windows: robots taken out of service, quiet in every output at once, and saying why.

What a window is lives with the model (`model/maintenance.py`); here: `store` keeps the one-off windows
in the exporter's SQLite database, `schedule` is the one owner of the windows (validating, starting and
ending them, telling each robot's state, and the events of their starts and ends), `requests` reads a
window from an API request.
"""
