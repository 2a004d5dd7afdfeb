"""Simulation: twins of the drives and the MuJoCo world they drive.

Rule: a twin = a protocol-free firmware (:mod:`joints.sim.firmware`; :mod:`joints.sim.erob`,
:mod:`joints.sim.zlac`: state machine, modes, profile generator, loops, motor model, faults,
watchdog) + thin protocol fronts that turn frames into firmware calls by parameter name
(:mod:`joints.sim.modbus_front`) + the MuJoCo coupling (:mod:`joints.sim.world`); served over pty
/ python-can channels (:mod:`joints.sim.serve`). Uses devices, codecs and transports only.
"""
