"""Live mode: streaming from an articulograph, biofeedback targets, sweeps.

The stream (no Qt here, see :mod:`tonguevis.gui` for the live view):

* :mod:`tonguevis.live.rtc3d` — the NDI WaveFront real-time protocol's bytes (packets, 6D frames).
* :mod:`tonguevis.live.source` — the :class:`~tonguevis.live.source.Source` interface, the
  WaveFront client (reconnecting) and a recording played in-process.
* :mod:`tonguevis.live.server` — a replay server speaking the protocol from any recording.
* :mod:`tonguevis.live.recorder` — a stream written as an NDI Wave TSV as it arrives.
* :mod:`tonguevis.live.simulator` — the tongue simulated frame by frame from the stream (the
  replay's model and constraints; the rest from a still moment).
* :mod:`tonguevis.live.session` — a live session: the source, the simulation, the rest
  (:mod:`~tonguevis.live.rest`), the targets and sweeps (:mod:`~tonguevis.live.session_targets`),
  the counters, the display's low-pass (:mod:`~tonguevis.live.display_filter`), the palatogram
  (:mod:`~tonguevis.live.palatogram`), with events; what the live window shows, and what a script runs.
"""
