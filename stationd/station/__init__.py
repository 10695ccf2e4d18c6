"""The station: bolt matching, the tightening cycle's state machine, the daemon, sd_notify."""
