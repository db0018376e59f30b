"""``tonguevis stream FILE``: serve a recording over the NDI WaveFront real-time protocol (a replay server)."""

from __future__ import annotations

import argparse

DEFAULT_HOST, DEFAULT_PORT = "127.0.0.1", 3030


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from tonguevis.cli._common import DeprecatedAlias, add_reader_options_argument

    parser.add_argument("file", help="an EMA recording in any format tonguevis reads")
    parser.add_argument("--sensors", metavar="MAP",
                        help="sensor map: a preset (paper, haskins, mngu0) or a JSON file of name -> channel "
                             "(default: sensor_map.json beside the file, if there is one); its names are sent "
                             "with the slots")
    parser.add_argument("--format", metavar="NAME", help="read as this format instead of detecting it")
    add_reader_options_argument(parser)
    # HOST:PORT in one option, as record and live take their --source; --host/--port were its old spelling.
    parser.add_argument("--listen", default=f"{DEFAULT_HOST}:{DEFAULT_PORT}", metavar="HOST:PORT",
                        help=f"address and TCP port to listen on (default {DEFAULT_HOST}:{DEFAULT_PORT}: this machine "
                             "only, WaveFront's port; 0.0.0.0:3030 every network; port 0: any free one)")
    parser.add_argument("--host", action=DeprecatedAlias, new="--listen HOST:PORT")
    parser.add_argument("--port", type=int, action=DeprecatedAlias, new="--listen HOST:PORT")
    parser.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    parser.add_argument("--speed", type=float, default=1.0, help="playback speed factor (default 1.0: the "
                                                                 "recording's own rate)")


def run(args) -> int:
    from tonguevis.cli._common import parse_options
    from tonguevis.cli.record import parse_address
    from tonguevis.errors import TonguevisError
    from tonguevis.live.server import ReplayServer, serve_until_done
    from tonguevis.workflows.recording import open_recording

    if not args.speed > 0:
        raise TonguevisError(f"--speed must be positive, not {args.speed}")
    host, port = parse_address(args.listen, DEFAULT_PORT, option="--listen", any_port=True)
    host = args.host if args.host is not None else host  # the deprecated spellings still work
    port = args.port if args.port is not None else port
    rec = open_recording(args.file, args.sensors, format=args.format, audio=False, labels=False,
                         **parse_options(args.option))
    if rec.n_samples == 0:
        raise TonguevisError("the recording has no samples to stream", args.file)
    server = ReplayServer(rec, host=host, port=port, speed=args.speed, loop=args.loop)
    port = server.start()
    slots = ", ".join(f"{k}:{name}" for k, name in enumerate(server.names))
    print(f"streaming {args.file} ({rec.n_samples} frames at {rec.rate:g} Hz, {rec.duration:.1f} s"
          f"{', looped' if args.loop else ''}, speed {args.speed:g}) on {host}:{port}", flush=True)
    print(f"sensor slots {slots}; the stream starts when a client asks for frames; Ctrl-C stops", flush=True)
    if not server.local_only:  # 127.0.0.2 is this machine too; 0.0.0.0 or a network address is not
        print(f"note: listening on {host}: other machines that reach this one can connect", flush=True)
    try:
        serve_until_done(server, report=lambda text: print(text, flush=True), interval=5.0)
        print(f"end of the recording: {server.frames_sent} frames sent to {server.connections} connection(s)"
              + ("" if args.loop else " (--loop repeats it)"), flush=True)
    except KeyboardInterrupt:
        print(f"stopped: {server.frames_sent} frames sent to {server.connections} connection(s)", flush=True)
    finally:
        server.stop()
    return 0
