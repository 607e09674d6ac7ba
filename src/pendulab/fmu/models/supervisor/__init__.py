"""Supervisor FMU: the lab control logic (SPEC §5). See :mod:`.config` for its variables and codes."""
