"""Reading meshes from two threads at once leaves sys.stdout and sys.stderr as they were.

quiet_meshio_read captures meshio's chatter by swapping the process's streams; two reads that
interleaved their swaps (the app reads the palate for a compared recording beside the open one)
left sys.stdout pointing at one of the captures for good, and every later print was lost.
"""

from __future__ import annotations

import sys
import threading
import time

import meshio

from tonguevis.mesh import readers


def test_two_overlapping_reads_give_the_streams_back(monkeypatch):
    inside_second = threading.Event()
    first_in = threading.Event()

    def slow_read(path):
        if path == "first":
            first_in.set()
            inside_second.wait(0.5)  # without one read at a time the second comes in here, then leaves last
        else:
            inside_second.set()
            time.sleep(0.2)
        return path

    monkeypatch.setattr(meshio, "read", slow_read)
    out, err = sys.stdout, sys.stderr
    results = []
    first = threading.Thread(target=lambda: results.append(readers.quiet_meshio_read("first")))
    second = threading.Thread(target=lambda: results.append(readers.quiet_meshio_read("second")))
    first.start()
    first_in.wait(5)
    second.start()
    first.join(10)
    second.join(10)
    assert sorted(results) == ["first", "second"]
    assert sys.stdout is out and sys.stderr is err
