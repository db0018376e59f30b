"""``tonguevis record --source HOST:PORT --out DIR``: record a live stream as an NDI Wave TSV (and its
head-corrected version), written as it arrives."""

from __future__ import annotations

import argparse
import time


def parse_address(text: str, default_port: int = 3030, option: str = "--source",
                  any_port: bool = False) -> tuple[str, int]:
    """``"HOST:PORT"`` (or ``"HOST"``, ``"[::1]:PORT"``) -> (host, port): every network address a command
    takes (``record``/``live --source``, ``stream --listen``) is written so.  ``any_port``: port 0 (any
    free one) is allowed, for listening; ``option`` names the option in errors."""
    from tonguevis.errors import TonguevisError

    host, sep, port = text.strip().rpartition(":")
    if not sep or (host.count(":") and not host.startswith("[")):
        host, port = text.strip(), str(default_port)  # no port, or a bare IPv6 address
    host = host.strip("[]")
    try:
        number = int(port)
    except ValueError:
        raise TonguevisError(f"{option} {text!r}: the port {port!r} is not a number (expected HOST:PORT)") from None
    if not host or not (0 if any_port else 1) <= number < 65536:
        raise TonguevisError(f"{option} {text!r} is not HOST:PORT")
    return host, number


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # dest "address": the device's, not a recording (other commands' "source" is a file).
    parser.add_argument("--source", dest="address", required=True, metavar="HOST:PORT",
                        help="the NDI WaveFront real-time server (e.g. 192.168.1.10:3030, or a "
                             "`tonguevis stream` on 127.0.0.1:3030)")
    parser.add_argument("--out", required=True, metavar="DIR", help="folder to write the recording in")
    parser.add_argument("--seconds", type=float, metavar="N", help="stop after N seconds (default: until Ctrl-C "
                                                                   "or the stream ends)")
    parser.add_argument("--name", help="file name without .tsv (default: sweep_YYYYMMDD_HHMMSS); never overwrites")
    parser.add_argument("--sensors", metavar="MAP",
                        help="names of the slots: a preset or a JSON file of name -> NDI Id (default: the names "
                             "the device sends, if any); three REF* names give the head-corrected file")
    parser.add_argument("--capture", action="store_true",
                        help="also keep every byte the device sent, raw, in NAME.rtc3d (golden files of a real "
                             "device for tests; tonguevis.live.rtc3d.read_capture reads them)")
    parser.add_argument("--stall", type=float, default=2.0, metavar="S",
                        help="seconds without data before the connection is reopened (default 2)")
    parser.add_argument("--retries", type=int, default=5, metavar="N",
                        help="failed reconnection attempts in a row before giving up (default 5)")


def run(args) -> int:
    from tonguevis.errors import TonguevisError
    from tonguevis.live.recorder import free_path, record
    from tonguevis.live.source import WaveFrontSource

    if args.seconds is not None and not args.seconds > 0:
        raise TonguevisError(f"--seconds must be positive, not {args.seconds}")
    host, port = parse_address(args.address)
    name = args.name or time.strftime("sweep_%Y%m%d_%H%M%S")
    if not name or any(c in name for c in "/\\") or name in (".", ".."):
        raise TonguevisError(f"--name {name!r} is not a file name")
    path = free_path(args.out, name)
    say = lambda text: print(text, flush=True)  # noqa: E731
    capture = path.with_suffix(".rtc3d") if args.capture else None
    source = WaveFrontSource(host, port, stall_timeout=args.stall, max_retries=args.retries, on_event=say,
                             capture=capture)
    say(f"recording {host}:{port} into {path}" + (f" for {args.seconds:g} s" if args.seconds else "")
        + "; Ctrl-C stops and keeps the file")
    source.start()
    result = record(source, path, seconds=args.seconds, sensor_map=args.sensors, report=say)
    st = result.status
    if result.path is None:  # an error like any other: one line on stderr, exit status 2
        raise TonguevisError(f"nothing recorded: no frame arrived from {host}:{port}"
                             + (f" ({st.errors[-1]})" if st.errors else ""))
    how = "stopped by Ctrl-C" if result.interrupted else ("the stream ended" if st.state == "failed" else "done")
    say(f"{how}: {result.frames} frames ({result.seconds:.1f} s) in {result.path}"
        + (f"; {st.missed} frames missed by the device" if st.missed else "")
        + (f"; {st.dropped} dropped" if st.dropped else "")
        + (f"; {st.reconnects} reconnection(s)" if st.reconnects else ""))
    for note in result.notes:
        say(note)
    if source.captured:
        say(f"raw bytes received: {', '.join(str(p) for p in source.captured)}")
    return 0
