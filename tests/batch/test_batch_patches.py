"""A batch resumed from a saved motion with sensor patches segments as a fresh one (the saved motion's
own model, modes and patches, is kept: the batch's plain model used to replace it)."""

from __future__ import annotations

import numpy as np

from tonguevis.cli import main
from tonguevis.paths import DATA_DIR


def test_resumed_patched_batch_equals_a_fresh_one(tmp_path):
    demo = str(DATA_DIR / "spk1_ta.tsv")
    common = ["--sensor-patches", "--modes", "30", "--segment-first", "1", "--quiet"]
    assert main(["batch", demo, "--out", str(tmp_path / "a"), "--steps", "simulate", *common]) == 0
    assert main(["batch", demo, "--out", str(tmp_path / "a"), "--steps", "simulate,segment", *common]) == 0
    assert main(["batch", demo, "--out", str(tmp_path / "b"), "--steps", "simulate,segment", *common]) == 0
    with np.load(tmp_path / "a" / "recordings" / "spk1_ta" / "segmentation.npz") as resumed, \
            np.load(tmp_path / "b" / "recordings" / "spk1_ta" / "segmentation.npz") as fresh:
        np.testing.assert_array_equal(resumed["labels"], fresh["labels"])
