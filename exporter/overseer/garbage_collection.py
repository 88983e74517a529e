"""When Python's cycle collector runs in a process holding a fleet: after 100,000 new objects, not 700.

The fleet model is large and long-lived (at 10,000 robots, a million tracked objects), and every message
replaces a few of its objects with new ones that live until the robot's next message. With Python's
default thresholds the collector ran its youngest generation about 60 times a second, and those objects,
promoted by it, kept the oldest generation due for a full pass every few seconds: 200-600 ms with the
interpreter lock held, which no thread of the process could use. At 10,000 robots x 50 components at
1 Hz over Zenoh (`bench.bench_scale`, one worker) the collector took 9.8 s of CPU in a 75 s run, with 19
full passes of up to 609 ms; with these thresholds 3 s and none. In process (`bench.bench_collector`) a
robot's first array costs 450 µs instead of 573.

A collection starts when the tracked objects allocated exceed those freed by the first threshold. In a
steady fleet the two balance, so at 100,000 the collector does not run at all; when the process does
grow (a fleet first heard), it runs a hundred times less often. Garbage in reference cycles is still
collected, 100,000 objects at the latest; the model itself makes none. What a cycle holds stays until
then, which in a steady fleet is about never: a failure raised while a local of its own frame names it
is such a cycle, and keeps every caller's frame (`push/icinga2_client.py` raises its failures unnamed).
"""

from __future__ import annotations

import gc

YOUNG_THRESHOLD = 100_000  # new tracked objects (allocated minus freed) before the youngest generation
OLDER_THRESHOLDS = (10, 10)  # Python's own: collections of a generation before the next one's


def collect_in_large_batches() -> None:
    """Set this process's collector thresholds for a large, long-lived model (call once, at start)."""
    gc.set_threshold(YOUNG_THRESHOLD, *OLDER_THRESHOLDS)
