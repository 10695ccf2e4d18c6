"""Camera model, stereo geometry, calibration and frames (no image processing here)."""
