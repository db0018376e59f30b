"""``tonguevis formats``: the recordings tonguevis reads and what it writes (the export table the app's
File ▸ Export menu is built from, :mod:`tonguevis.workflows.exports`)."""

from __future__ import annotations


def add_arguments(parser) -> None:
    parser.add_argument("--exports", action="store_true", help="only what tonguevis writes")


def run(args) -> int:
    from tonguevis.io.registry import registered_formats
    from tonguevis.workflows.exports import exports_text

    if not args.exports:
        print("Recordings it reads (and writes, with tonguevis convert):")
        for fmt in registered_formats().values():
            mode = "read" + ("/write" if fmt.write else "") if fmt.read else "write"
            print(f"  {fmt.name:<11} {', '.join(fmt.extensions)} ({mode}): {fmt.description}")
        print()
    print("What it writes:")
    for line in exports_text().splitlines():
        print(f"  {line}")
    return 0
