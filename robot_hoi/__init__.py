"""robot-hoi: human-object-interaction MoCap -> G1 + Inspire policies.

Pipeline (dependencies point one way): data -> embodiment/sim -> rl -> export -> deploy -> sim2sim.
"""

__version__ = "0.1.0"
