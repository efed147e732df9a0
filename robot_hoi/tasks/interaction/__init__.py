"""Human-object interaction imitation on the robot (InterMimic teachers)."""
