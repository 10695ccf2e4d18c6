"""Tests of the camera drivers: Aravis's fake GigE camera on loopback, files, the sim channel."""
