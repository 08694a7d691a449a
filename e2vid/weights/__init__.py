"""Weights this project trained itself (see README.md here for how they were made)."""
from pathlib import Path

SHIPPED = "firenet_sim.pth"


def default_weights_path() -> Path:
    path = Path(__file__).with_name(SHIPPED)
    if not path.exists():
        raise FileNotFoundError(f"{path}: the shipped E2VID weights are missing (train them with "
                                f"`e4dgs train-e2vid --export {path}`)")
    return path
