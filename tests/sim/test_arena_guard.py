"""A world whose MuJoCo arena fills up leaves the fused compiled step: an arena overflow then raises
``mujoco.FatalError`` (the rig's exit handling runs) instead of ending the process."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

ROOT = Path(__file__).resolve().parents[2]


def _crowded_model(tmp_path: Path) -> Path:
    src = (ROOT / "models" / "erob_stand.xml").read_text(encoding="utf-8")
    boxes = "".join(f'<body pos="{0.5 + 0.02 * (i % 10)} {0.02 * (i // 10)} {0.05 + 0.01 * i}"><freejoint/>'
                    f'<geom type="box" size="0.01 0.01 0.01"/></body>' for i in range(100))
    src = src.replace("<worldbody>", "<worldbody>" + boxes).replace(
        '<option timestep="0.001" integrator="implicitfast"/>',
        '<option timestep="0.001" integrator="implicitfast"/><size memory="800K"/>')
    path = tmp_path / "crowded.xml"
    path.write_text(src, encoding="utf-8")
    return path


def test_an_arena_overflow_raises_instead_of_ending_the_process(tmp_path: Path) -> None:
    model = _crowded_model(tmp_path)
    script = textwrap.dedent(f"""
        import joints, mujoco
        cfg = {{"sim": {{"model": {str(model)!r}}}, "buses": {{"b": {{"protocol": "modbus-rtu"}}}},
                "joints": {{"joint1": {{"device": "erob", "bus": "b", "address": 1}}}}}}
        try:
            with joints.open(cfg) as rig:
                rig.sleep(2.0)
        except mujoco.FatalError as exc:
            print("raised", "out of memory" in str(exc), rig.closed)
    """)
    proc = subprocess.run([sys.executable, "-c", script], cwd=ROOT, capture_output=True, text=True, timeout=120,
                          check=False)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["raised", "True", "True"], (proc.stdout, proc.stderr)
    assert "stepping without the fused compiled call" in proc.stderr
