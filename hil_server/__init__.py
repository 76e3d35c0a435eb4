"""HydroHIL service: the plant at a fixed rate behind a CompactFieldPoint-like interface (REST, CAN)."""
