"""The co-simulation: the master (FMU, controller process over zenoh, CAN frames) and
its MCAP recordings."""
