"""Helpers shared by the test suite: free ports, DDS domains, and the project's own processes."""
