"""MDP terms of the interaction task: each one short, pure, batched function `(env, **params) -> Tensor`."""
