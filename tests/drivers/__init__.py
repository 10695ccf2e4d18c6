"""Tests of the device drivers, over their real protocols."""
