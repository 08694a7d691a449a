"""A training run's folder bookkeeping: its identity file (run.json, config.yaml), the precision of
each start, the log file, and the removal of what a run that failed before its first checkpoint wrote.

    folder = RunFolder(out, method="d3dgs", fingerprint="...")
    folder.claim(scene_dir, config_dict, config_yaml)   # new folder: writes run.json; else checks it is this run
"""
from __future__ import annotations

import contextlib
import json
from pathlib import Path

from common.fileio import write_text_atomic


class ForeignRunError(RuntimeError):
    """The folder holds a different run (another config or dataset)."""


class RunFolder:
    def __init__(self, out: Path, method: str, fingerprint: str):
        self.out, self.method, self.fingerprint = Path(out), method, fingerprint

    @property
    def run_json(self) -> Path:
        return self.out / "run.json"

    def claim(self, scene_dir: Path, config: dict, config_yaml: str) -> None:
        """Write run.json and config.yaml into a new folder, or check that an existing one is this run."""
        if self.run_json.exists():
            info = json.loads(self.run_json.read_text())
            if info.get("fingerprint") != self.fingerprint:
                raise ForeignRunError(
                    f"{self.out}: holds a different run (method {info.get('method')!r}, fingerprint "
                    f"{info.get('fingerprint')}; this run is {self.method!r}, {self.fingerprint}: the "
                    "config or the dataset differ). Use another output folder or delete this one.")
            return
        self.out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(self.run_json, json.dumps({"method": self.method, "fingerprint": self.fingerprint,
                                                     "scene_dir": str(Path(scene_dir).resolve()), "config": config},
                                                    indent=1))
        write_text_atomic(self.out / "config.yaml", config_yaml)

    def record_precision(self, from_iteration: int, choice: dict) -> None:
        """One start's deformation precision in run.json's `precision` list (a resumed `auto` run measures
        again on the machine it resumes on)."""
        starts = json.loads(self.run_json.read_text()).get("precision", [])
        self.record("precision", starts + [{"from_iteration": from_iteration, **choice}])

    def record(self, key: str, value) -> None:
        """A fact of this run in run.json (e.g. `init_fallback`: the initialisation used instead of the
        configured one, and why)."""
        info = json.loads(self.run_json.read_text())
        info[key] = value
        write_text_atomic(self.run_json, json.dumps(info, indent=1))

    def write_log(self, rows: list[dict]) -> None:
        write_text_atomic(self.out / "log.jsonl", "".join(json.dumps(r) + "\n" for r in rows))

    def remove_unresumable(self) -> None:
        """After a failure of a run that started in this folder and saved no checkpoint (nothing to resume),
        remove what it wrote, so that no folder with a run.json but no model looks like a run."""
        if (self.out / "checkpoint.pt").exists() or (self.out / "model.pt").exists():
            return
        for name in ("run.json", "config.yaml", "log.jsonl"):
            (self.out / name).unlink(missing_ok=True)
        snaps = self.out / "snapshots"
        if snaps.is_dir():
            for f in snaps.glob("*.pt"):
                f.unlink()
            with contextlib.suppress(OSError):
                snaps.rmdir()
        with contextlib.suppress(OSError):     # only if nothing else is in it (a user's own files stay)
            self.out.rmdir()
