"""Outputs that push the fleet's state to other servers (Icinga 2), from model snapshots."""
