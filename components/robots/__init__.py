"""Robot descriptions: one folder per robot, holding a URDF and a small TOML of metadata."""
from __future__ import annotations

from pathlib import Path

ROBOTS_DIR = Path(__file__).resolve().parent


def available() -> list[str]:
    """Names of the robots described in this package, sorted."""
    return sorted(p.name for p in ROBOTS_DIR.iterdir() if (p / f"{p.name}.toml").is_file())


def description_path(name: str) -> Path:
    """Path of robot ``name``'s metadata TOML; ValueError naming the known robots otherwise."""
    path = ROBOTS_DIR / name / f"{name}.toml"
    if not path.is_file():
        raise ValueError(f"unknown robot {name!r}; known robots: {', '.join(available())}")
    return path
