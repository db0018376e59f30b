"""``tonguevis live [--source HOST:PORT]``: the live view of an articulograph's stream (or a replay server's)."""

from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--source", dest="address", metavar="HOST:PORT",
                        help="the NDI WaveFront real-time server to connect to at once (e.g. 192.168.1.10:3030, or "
                             "`tonguevis stream FILE` on 127.0.0.1:3030); default: connect from the window")
    parser.add_argument("--sensors", metavar="MAP",
                        help="names of the slots: a preset or a JSON file of name -> NDI Id (default: the names the "
                             "device sends, else the profile's)")
    parser.add_argument("--profile", metavar="ID",
                        help="the patient's profile (an id in the profiles folder, or a profile.json): its targets, "
                             "offsets and sensor map; sweeps are saved in its folder (default: the profile 'default')")
    from tonguevis.cli._common import add_run_arguments

    add_run_arguments(parser, quiet=False)  # the replay's options: the same tongue, frame by frame


def run(args) -> int:
    from tonguevis.cli._common import run_settings_of
    from tonguevis.cli.record import parse_address
    from tonguevis.live.simulator import check_live_settings

    settings = run_settings_of(args)  # said before Qt: a bad setting or palate file, one line naming it
    check_live_settings(settings)
    address = None
    if args.address:
        host, port = parse_address(args.address)  # a clear error for a bad HOST:PORT, before any window
        address = f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
    sensor_map = None
    if args.sensors:
        from tonguevis.io.sensor_map import load_sensor_map

        sensor_map = dict(load_sensor_map(args.sensors))
    profile = None
    if args.profile:
        from tonguevis.live.profiles import load_profile

        profile = load_profile(args.profile)
    from tonguevis.gui.live_window import run_live  # the one way into Qt (pyproject's import contracts)

    return run_live(address, settings, sensor_map=sensor_map, profile=profile)
