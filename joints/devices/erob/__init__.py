"""ZeroErr eRob rotary actuators: register table and physical device profiles."""
