"""Job queue wiring: Huey carries job ids; handlers live in the services."""
