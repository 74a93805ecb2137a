"""lfsim: a Mitsuba 3 simulator of a plenoptic camera behind a flat port, with ground truth.

Importing this package does not import Mitsuba; :func:`simulator.backend.load_mitsuba` does.
"""
