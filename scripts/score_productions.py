"""Score the production finder against the hand labels of the shared real recordings.

For each labelled recording (``NAME.labels.TextGrid`` beside it, tiers ``syllables`` and
``release``; stretches in ``ambiguous`` are neither right nor wrong) runs what
``tonguevis syllables FILE --all`` runs and prints: productions found and labelled, how
many starts (releases) match a labelled release one to one within 60 ms, the median and
largest error of the matched ones, and the misses and extras.  Reads the files in place
(``../shared/data/ema/optispeech`` by default); prints summary figures only.

    python scripts/score_productions.py [--data DIR] [--json OUT]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tonguevis.paths import REPO_DIR


def main(argv=None) -> int:
    from tonguevis.analysis.production_scores import labelled_recordings, score_against_labels
    from tonguevis.workflows import find_recording_productions, open_recording

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=REPO_DIR.parent / "shared" / "data" / "ema" / "optispeech")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    files = labelled_recordings(args.data)
    if not files:
        print(f"no labelled recordings in {args.data}", file=sys.stderr)
        return 1
    out = {}
    for path, labels_path in files:
        rec = open_recording(path)
        table = find_recording_productions(rec, keep=None)
        score = score_against_labels(table, labels_path)
        out[path.name] = score
        print(f"{path.name}: {table.articulator} ({table.articulator_reason}); found {score['found']} "
              f"(outside ambiguous stretches), labelled {score['labelled']}; matched {score['matched']} within "
              f"{1000 * score['tolerance_s']:.0f} ms, median error {score['median_error_ms']:.1f} ms, "
              f"largest {score['max_error_ms']:.1f} ms; missed {score['missed']}, extra {score['extra']}; "
              f"clear: {table.clear}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
