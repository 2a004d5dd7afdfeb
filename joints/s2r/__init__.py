"""Sim-to-real: identify a joint into its twin, shadow real joints with twins, record and replay bus traffic.

Rule: this layer uses only the public rig/joint API (and the sim world for twins it builds
itself), so everything here runs the same on hardware and on a twin. Heavy imports (numpy,
MuJoCo, python-can, matplotlib) happen inside the functions that need them.

* :mod:`joints.s2r.identify` - system identification through the Joint API (``joints identify``)
  and the device-profile overlay it writes (joint key ``profile_overlay``);
* :mod:`joints.s2r.shadow` - a twin beside each real joint, fed the same frames, divergence and plot;
* :mod:`joints.s2r.record` - record a run's bus frames; replay them against fresh twins and diff.
"""
