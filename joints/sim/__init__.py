"""Simulation: emulated drives (device semantics + motor model + MuJoCo coupling) and servers."""
