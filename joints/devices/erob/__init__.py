"""ZeroErr eRob: register table, parameters, profiles and faults (pure data)."""
