"""Benchmarks: commands that print figures (accuracy and speed), never pass/fail tests."""
