"""The real-time engine: the plant stepped at a fixed rate in its own process."""
