"""The core does not depend on the device layer: importing every module of layerskin_exp (the
simulated world, the vision module, the session log) loads nothing from `hardware`."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_layerskin_exp_never_imports_hardware():
    code = (
        "import importlib, pkgutil, sys\n"
        "import layerskin_exp\n"
        "for m in pkgutil.walk_packages(layerskin_exp.__path__, 'layerskin_exp.'):\n"
        "    if m.name.endswith('__main__') or m.name in ('layerskin_exp.demo',):\n"
        "        continue\n"
        "    importlib.import_module(m.name)\n"
        "bad = sorted(k for k in sys.modules if k == 'hardware' or k.startswith('hardware.'))\n"
        "print(','.join(bad))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "", f"layerskin_exp imports {r.stdout.strip()}"
