"""Physics behind one interface: batched torch tensors in and out (see backend.PhysicsBackend)."""

from robot_hoi.sim.backend import PhysicsBackend, make_backend

__all__ = ["PhysicsBackend", "make_backend"]
