"""MKS SERVO42D/57D closed-loop steppers: parameters, native and Modbus maps, run state machine, profiles.

Pure data and pure functions shared by the driver and the twin (see each module's docstring):
``params`` (MKS_PARAMS), ``native`` (command codes and the native map), ``modbus`` (the Part 8
map), ``state`` (work modes, codes, run state machine, acceleration and microstep laws),
``profile`` (SERVO42D / SERVO57D physical profiles).
"""
