"""OpenMP's wait policy: every package sets OMP_WAIT_POLICY=PASSIVE (unless the user set one) before
torch or numba load OpenMP, which reads it once (docs/design/recon.md, "Threads")."""
import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ["common", "simulator", "scene_format", "datagen", "blender_scenes", "recon", "benchmark", "e2vid",
            "viewer", "e4dgs"]
# records OMP_WAIT_POLICY at the moment torch / numba are first imported, then imports the module asked for
PROBE = """
import importlib, importlib.abc, json, os, sys
seen = {}
class Probe(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name in ("torch", "numba") and name not in seen:
            seen[name] = os.environ.get("OMP_WAIT_POLICY")
sys.meta_path.insert(0, Probe())
importlib.import_module(sys.argv[1])
print(json.dumps(seen))
"""


def test_every_package_imports_common_before_anything_else():
    for pkg in PACKAGES[1:]:
        tree = ast.parse((ROOT / pkg / "__init__.py").read_text())
        imports = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
        assert imports, f"{pkg}/__init__.py imports nothing: its modules could load torch before common"
        first = imports[0]
        names = [a.name for a in first.names] if isinstance(first, ast.Import) else [first.module]
        assert names[0].split(".")[0] == "common", f"{pkg}/__init__.py: first import is {names[0]}, not common"


@pytest.mark.parametrize("module, preset, expected", [
    ("viewer.app", None, "PASSIVE"), ("e2vid.train", None, "PASSIVE"), ("recon.deform", None, "PASSIVE"),
    ("recon.deform", "ACTIVE", "ACTIVE")])   # a value the user set is kept
def test_torch_and_numba_load_with_the_policy(module, preset, expected):
    import json

    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if preset:
        env["OMP_WAIT_POLICY"] = preset
    out = subprocess.run([sys.executable, "-c", PROBE, module], cwd=ROOT, env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    seen = json.loads(out.stdout.strip().splitlines()[-1])
    assert "torch" in seen and set(seen.values()) == {expected}, seen
