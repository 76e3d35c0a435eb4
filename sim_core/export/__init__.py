"""The plant in other tools' formats (FMI co-simulation FMU). Everything here reads a RobotSpec and
drives the public Plant/Context/Simulator API; nothing in the rest of sim_core imports it."""
