"""The reliability harness (issue 18): fuzzing of every codec and twin endpoint, transactions under faults.

Run it as one command (``python tests/harness/run.py --count N --seed S``); ``test_harness.py``
runs a small seeded slice in CI. Not part of the installed library: it imports ``joints`` like
any user, plus the vendored test vectors (``tests/testdata.py``).

Modules: :mod:`report` (counts per target and invariant), :mod:`corpus` (frames from the vectors,
mutators, random valid frames per protocol), :mod:`codec_fuzz` (every codec, both roles),
:mod:`endpoint_fuzz` (every twin endpoint the registry builds), :mod:`transactions` (driver
access -> link -> faulty transport -> twin, in process or over a pty), :mod:`run` (the command).
"""
