#!/usr/bin/env python
"""Benchmark the live stream's core, without any display: codec cost and socket latency on this machine.

* ``decode_us``: microseconds to read and decode one 6D frame of 16 sensors (the most an
  NDI Wave sends) from bytes (:class:`~tonguevis.live.rtc3d.PacketReader` + ``decode_data``).
* ``latency_ms``: from the moment the replay server's clock says a frame is due to the
  moment the WaveFront client has it decoded (its ``arrival_s``, read at the socket, both
  on one ``perf_counter``): the replay server's scheduling plus TCP on localhost plus the
  reader thread.  Median, p95 and max over the demo streamed at its own rate.
* ``frames``, ``missed``, ``dropped`` and the frames per second received.

The live view's own latency (socket to painted frame) is measured by ``bench_live.py``;
this script gives the part before it.

    python scripts/bench_live_stream.py --json bench_live_stream.json
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def decode_cost(repeats: int = 20000) -> float:
    from tonguevis.live.rtc3d import PacketReader, decode_data, encode_6d_frame

    rng = np.random.default_rng(0)
    packets = [encode_6d_frame(k, 10_000 * k, rng.normal(size=(16, 3)) * 50, rng.normal(size=(16, 4)))
               for k in range(100)]
    stream = b"".join(packets)
    reader = PacketReader()
    start = time.perf_counter()
    n = 0
    for _ in range(repeats // 100):
        for p in reader.feed(stream):
            decode_data(p.payload)
            n += 1
    return (time.perf_counter() - start) / n * 1e6


def stream_latency(seconds: float, speed: float) -> dict:
    from tonguevis.live.server import ReplayServer
    from tonguevis.live.source import WaveFrontSource
    from tonguevis.paths import DEMO_RECORDING
    from tonguevis.workflows import open_recording

    rec = open_recording(DEMO_RECORDING)
    latencies, frames = [], 0
    with ReplayServer(rec, speed=speed, loop=True) as server:
        source = WaveFrontSource("127.0.0.1", server.port).start()
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            frame = source.get(0.5)
            if frame is None:
                continue
            frames += 1
            latencies.append(frame.arrival_s - server.next_due(frame.frame - 1))
        elapsed = time.perf_counter() - start
        source.close()
    st = source.status()
    ms = np.array(latencies) * 1000.0
    return {"latency_ms": {"median": float(np.median(ms)), "p95": float(np.percentile(ms, 95)),
                           "max": float(ms.max())},
            "frames": frames, "frames_per_second": frames / elapsed, "missed": st.missed, "dropped": st.dropped,
            "reconnects": st.reconnects}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0, help="how long to stream (default 10)")
    parser.add_argument("--speed", type=float, default=1.0, help="playback speed of the demo (default 1: 100 Hz)")
    parser.add_argument("--json", help="write the figures to this JSON file too")
    args = parser.parse_args()
    result = {"decode_us": decode_cost(), **stream_latency(args.seconds, args.speed),
              "speed": args.speed, "load_average": os.getloadavg()}
    print(json.dumps(result, indent=1))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
