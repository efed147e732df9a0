"""Reinforcement learning core: PPO (InterMimic Table C), rollout storage, actor-critic, runner.

Kept import-light on purpose: the commands import `robot_hoi.rl.config` and `robot_hoi.rl.recipe` when the CLI
builds its parser, so nothing here may pull in torch. Import the submodules you need (`robot_hoi.rl.runner`, `robot_hoi.rl.ppo`, ...).
"""
