"""The error type of the segmentation."""

from __future__ import annotations

from tonguevis.errors import TonguevisError


class SegmentationError(TonguevisError):
    """A segmentation could not run with the given mesh, target, seeds or file."""
