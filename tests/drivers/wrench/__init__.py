"""Tests of the tightening-controller drivers (Open Protocol over TCP and a pty)."""
