"""Real servers and simulated fleets on loopback, for the tests and the benchmarks alike.

Nothing here is part of the product: it starts the exporter, the simulator, Prometheus and the other
servers as a user would, on free ports, and stops them again.
"""
