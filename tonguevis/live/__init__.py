"""Live mode: streaming from an articulograph, biofeedback targets, sweeps."""
