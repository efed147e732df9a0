"""Atomic file writes: the project's single implementation lives in deploy._atomic (deploy must not import
robot_hoi, so robot_hoi imports it from there)."""

from deploy._atomic import atomic_path, atomic_write_bytes, atomic_write_text

__all__ = ["atomic_path", "atomic_write_bytes", "atomic_write_text"]
