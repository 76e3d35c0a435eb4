"""CAN side of the emulator: the DBC, transports (python-can buses chosen by configuration) and the bridge."""
